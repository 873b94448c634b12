"""Stage 1 (paper §5.1): the apparent permeability K(w) of every sample, by Newton.

For each sample, F = F_el(w; K) + F_D(U, K, R, H) of the base model is solved for K
(Newton on log K, all samples at once; the elastic law is self-consistent, so K enters
it too). Where
the measured force does not exceed the elastic law by a fluid force of the right
sign there is no positive root: the sample gets NaN and is counted, never dropped
silently. The plateau (deeper part of each curve) gives one K per speed; a weighted
line of plateau K against log10(speed) gives the trend and its significance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
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

    @property
    def slope_significance(self) -> float:
        """|slope| in standard errors (> 3: K depends on speed; the base model leaves physics out)."""
        return abs(self.slope) / self.slope_std if self.slope_std > 0 else math.inf


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
    slope, slope_std = _weighted_slope(plateau)
    return ApparentPermeability(permeability, plateau, slope, slope_std)


def _weighted_slope(plateau: dict[str, dict[str, float]]) -> tuple[float, float]:
    """Slope of mean K against log10(speed), weights 1/std_error², and its standard error; NaN without two speeds
    (replicates at one speed gave real PAAm a slope of -0.12 ± 0.12 m² per decade, from a zero spread of speeds)."""
    rows = [
        p for p in plateau.values() if np.isfinite(p["mean"]) and np.isfinite(p["std_error"]) and p["std_error"] > 0
    ]
    x = np.log10([p["base_speed"] for p in rows])
    if np.unique(np.round(x, 3)).size < 2:  # equal up to rounding
        return math.nan, math.nan
    y = np.array([p["mean"] for p in rows])
    w = 1.0 / np.array([p["std_error"] for p in rows]) ** 2
    xm = (w * x).sum() / w.sum()
    sxx = (w * (x - xm) ** 2).sum()
    slope = (w * (x - xm) * y).sum() / sxx
    # The plateau scatter beyond its own error bars (model error) inflates the slope's error honestly.
    dof = max(len(rows) - 2, 1)
    chi2 = (w * (y - (y * w).sum() / w.sum() - slope * (x - xm)) ** 2).sum() / dof
    return float(slope), float(math.sqrt(max(chi2, 1.0) / sxx))
