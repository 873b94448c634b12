"""Stage 1 (paper §5.1): the apparent permeability K(w) of every sample, by Newton.

For each sample, F = F_el(w; K) + F_D(U, K, R, H) of the base model is solved for K
(Newton on log K, all samples at once; the elastic law is self-consistent, so K enters
it too). Where
the measured force does not exceed the elastic law by a fluid force of the right
sign there is no positive root: the sample gets NaN and is counted, never dropped
silently. The plateau (deeper part of each curve) gives one K per curve; a line of
plateau K against log10(speed), weighted by each plateau's error and the scatter between
curves, gives the trend and its significance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.special
import torch

from ptwin.data.recordings import APPROACH
from ptwin.physics.model import ForceModel, fluid_off, total
from ptwin.physics.samples import Samples


@dataclass
class ApparentPermeability:
    """K(w) per sample [m²] (NaN: no root) and its plateau per curve."""

    permeability: torch.Tensor  # (S,)
    plateau: dict[str, dict[str, float]]  # curve → {base_speed, mean, std_error, samples, without_root}
    slope: float  # d plateau K / d log10(speed) [m²/decade]
    slope_std: float
    slope_dof: int  # degrees of freedom of the scatter between curves (0: two curves, not measured)

    @property
    def slope_significance(self) -> float:
        """|slope| in standard errors."""
        return abs(self.slope) / self.slope_std if self.slope_std > 0 else math.inf

    @property
    def slope_p_value(self) -> float:
        """How often a slope this many standard errors from 0 arises where K does not depend on speed (two-sided;
        Student's t on ``slope_dof``; NaN where the scatter between curves is not measured)."""
        if self.slope_dof < 1 or not math.isfinite(self.slope_significance):
            return math.nan
        return float(2 * scipy.special.stdtr(self.slope_dof, -self.slope_significance))


def apparent_permeability(
    base: ForceModel, samples: Samples, start: float, iterations: int = 40, plateau_from: float = 0.5
) -> ApparentPermeability:
    """Newton from K = ``start`` [m²] on the base model ``base`` (no terms); the plateau is the part
    deeper than ``plateau_from`` × the curve's depth."""

    def residual(log_k):
        return samples.force - total(base.components(samples, log_k.exp()))

    def residual_and_slope(log_k):
        # A sample's residual depends on its own K alone: the gradient of their sum is each one's slope
        # (one reverse pass; forward AD cost fifteen times more here, its zero tangents taking a slow path).
        log_k = log_k.detach().requires_grad_(True)
        with torch.enable_grad():
            value = residual(log_k)
            (slope,) = torch.autograd.grad(value.sum(), log_k)
        return value.detach(), slope

    log_k = torch.full_like(samples.force, math.log(start))
    with torch.no_grad():
        for _ in range(iterations):
            value, slope = residual_and_slope(log_k)
            step = (value / slope).nan_to_num(0.0).clamp(-2.0, 2.0)
            log_k = log_k - step
            if step.abs().max() < 1e-12:
                break
        final = residual(log_k)
    solved = (final.abs() <= 1e-6 * samples.force.abs().clamp(min=samples.noise_floor)) & samples.in_contact
    permeability = log_k.exp().where(solved, torch.full_like(log_k, math.nan))

    plateau = {}
    for i, curve in enumerate(samples.curve_ids):
        approach = (samples.curve == i) & (samples.segment == APPROACH)
        mine = approach & samples.in_contact  # none on the reference curve: its approach is the elastic law
        deep = mine & (samples.depth >= plateau_from * samples.depth[mine].max()) if mine.any() else mine
        values = permeability[deep]
        values = values[~values.isnan() & ~fluid_off(values)]
        # Most of the plateau without a K its fluid force fixes (the force at or below the elastic law: no root; or K
        # at the field's limit or beyond): K there is a bound, no value, and the few samples noise lifted say nothing
        # (real agarose, a softer spot's 15 µm/s curve: 10 of 109 samples with a root, their mean 1.1e-14 m²).
        unfixed = bool(deep.any()) and values.numel() <= 0.5 * int(deep.sum())
        values = values[:0] if unfixed else values
        plateau[curve] = {
            "base_speed": samples.nominal_speed[approach][0].item() if approach.any() else math.nan,
            "mean": values.mean().item() if values.numel() else math.nan,
            "std_error": (values.std() / math.sqrt(values.numel())).item() if values.numel() > 1 else math.nan,
            "samples": int(values.numel()),
            "without_root": int((deep & permeability.isnan()).sum()),
            "unfixed": unfixed,
        }
    return ApparentPermeability(permeability, plateau, *_weighted_slope(plateau))


def _weighted_slope(plateau: dict[str, dict[str, float]]) -> tuple[float, float, int]:
    """(slope of mean K against log10(speed), its standard error, the degrees of freedom of the scatter between
    curves); NaN without two speeds (replicates at one speed gave real PAAm a slope of -0.12 ± 0.12 m² per decade,
    from a zero spread of speeds).

    A random-effects line (DerSimonian–Laird): each plateau's mean is off the line by its own error (``std_error``)
    and by a scatter between curves of variance τ², estimated from the weighted residual. A spot's own stiffness
    or contact moves its whole plateau, however many samples it has: weighted by its own error alone, as this line
    once was, two curves whose errors were tiny decided the slope, and the scatter scaled their errors, not added
    to them. On eleven simulated sets whose replicates' stiffness differs by 10% (no trend) it read 4.1, 4.5 and
    8.5 standard errors. The standard error is Knapp–Hartung's (the weighted residual's variance, at least what the
    plateaus' errors give), read on Student's t with n − 2 degrees of freedom: ``tests/test_apparent_permeability.py``
    measures how often a line through plateaus with no trend is called significant."""
    rows = [
        p for p in plateau.values() if np.isfinite(p["mean"]) and np.isfinite(p["std_error"]) and p["std_error"] > 0
    ]
    x = np.log10([p["base_speed"] for p in rows])
    if np.unique(np.round(x, 3)).size < 2:  # equal up to rounding
        return math.nan, math.nan, 0
    design = np.stack([np.ones_like(x), x], axis=1)
    y = np.array([p["mean"] for p in rows])
    variance = np.array([p["std_error"] for p in rows]) ** 2
    dof = len(rows) - 2

    def line(weight):
        normal = design.T @ (weight[:, None] * design)
        fit = np.linalg.solve(normal, design.T @ (weight * y))
        return fit, normal, (weight * (y - design @ fit) ** 2).sum()

    weight = 1.0 / variance
    _, normal, residual = line(weight)
    spread = weight.sum() - np.trace(np.linalg.solve(normal, design.T @ (weight[:, None] ** 2 * design)))
    between = max(0.0, (residual - dof) / spread) if dof > 0 else 0.0  # τ², method of moments
    fit, normal, residual = line(1.0 / (variance + between))
    scale = max(residual / dof, 1.0) if dof > 0 else 1.0
    return float(fit[1]), float(math.sqrt(scale * np.linalg.inv(normal)[1, 1])), dof
