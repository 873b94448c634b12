"""Evidence the curves give before any model: what replicates say about spot-to-spot
variation, what removed baselines say about drag, and the shape of the rate effect
(the force at equal depth, faster curves over the slowest). Sentences for the report,
and the numbers behind them."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from ptwin.data.contact import REJECT, baseline_levels
from ptwin.data.kinematics import CurveKinematics
from ptwin.data.recordings import APPROACH

SPOT_VARIATION = 0.05  # replicates differing by more than this are reported
DEPTH_POINTS = 50


@dataclass
class SpotVariation:
    spread: float  # largest relative difference in force at equal depth between replicates
    pair: tuple[str, str]
    base_speed: float  # [m/s]

    def sentence(self) -> str:
        a, b = self.pair
        return (
            f"Replicates {a} and {b} ({self.base_speed * 1e6:.3g} µm/s) differ by {100 * self.spread:.0f}% in force at "
            f"equal depth: the spots differ in stiffness, so the reference curve stands for the others only to about "
            f"that accuracy, and an effect smaller than that cannot be told from spot-to-spot variation."
        )


def spot_variation(curves: list[CurveKinematics]) -> SpotVariation | None:
    """The largest difference between curves at one base speed (replicates), or None without replicates."""
    groups = defaultdict(list)
    for curve in curves:
        groups[curve.base_speed].append(curve)
    worst = None
    for speed, group in groups.items():
        for i, a in enumerate(group):
            for b in group[i + 1 :]:
                spread = _force_ratio_spread(a, b)
                if spread is not None and (worst is None or spread > worst.spread):
                    worst = SpotVariation(spread, (a.curve, b.curve), speed)
    return worst


def _force_ratio_spread(a: CurveKinematics, b: CurveKinematics) -> float | None:
    """|median F_a/F_b − 1| over the deeper half of the depth both curves reach."""
    deepest = min(a.depth[a.in_contact].max(initial=0.0), b.depth[b.in_contact].max(initial=0.0))
    if deepest <= 0:
        return None
    grid = np.linspace(0.5 * deepest, deepest, DEPTH_POINTS)
    forces = []
    for curve in (a, b):
        use = curve.in_contact
        order = np.argsort(curve.depth[use])
        forces.append(np.interp(grid, curve.depth[use][order], curve.force[use][order]))
    positive = (forces[0] > 0) & (forces[1] > 0)
    if not positive.any():
        return None
    return float(abs(np.median(forces[0][positive] / forces[1][positive]) - 1.0))


def drag_from_baselines(curves: list[CurveKinematics]) -> str | None:
    """What the curves' baseline levels say about drag on the cantilever, by the test that decided which
    level was removed (``ptwin.data.contact.levels_with_speed``); None when no baseline was estimated."""
    removed = [c for c in curves if c.baseline is not None]
    if not removed:
        return None
    baselines = [c.baseline for c in removed]
    fit = baseline_levels(baselines, [c.base_speed for c in removed])
    listing = ", ".join(
        f"{c.curve} {c.baseline.level * 1e9:.3g} ± {c.baseline.level_std * 1e9:.2g} nN" for c in removed
    )
    drifting = max(b.level_drift for b in baselines)
    if drifting > 0:  # the errors listed hold it
        listing += (
            f" (each error holds up to {drifting * 1e9:.2g} nN for the drift the baselines' slopes show, which their "
            "own noise, read with their lines removed, does not)"
        )
    if fit is None:
        return (
            f"Baseline levels {listing}: too few curves and speeds (four curves at three speeds at least) to tell one "
            "level plus drag (b·speed) from free per-curve offsets; each curve's own level is removed, drag with it."
        )
    if fit.consistent and not fit.shows_drag:
        return (
            f"Baseline levels {listing} are one common level plus {fit.drag:.2g} ± {fit.drag_std:.1g} N s/m × speed "
            f"(χ² {fit.chi_square:.1f} on {fit.dof} degrees of freedom), but they rise with speed no more than free "
            f"per-curve offsets of their scatter would one time in {1 / REJECT:.0f} (t = {fit.rise:.1f}): each "
            "curve's own level is removed, drag with it."
        )
    if fit.shows_drag:
        return (
            f"Baseline levels {listing} are one common level plus {fit.drag:.2g} ± {fit.drag_std:.1g} N s/m × speed "
            f"(χ² {fit.chi_square:.1f} on {fit.dof} degrees of freedom): only the common level is removed, so drag "
            "on the cantilever, if any, stays in the force."
        )
    return (
        f"Baseline levels {listing} differ by more than one common level plus drag explains (χ² {fit.chi_square:.0f} "
        f"on {fit.dof} degrees of freedom, beyond the {fit.bound:.3g} such levels exceed one time in {1 / REJECT:.0f}, "
        "their errors read off their baselines): each curve's own level is removed, drag with it."
    )


RATIO_FLOOR = 20.0  # a force ratio is read only where the slow curve's force exceeds this many noise std
RATIO_BINS = 20
FASTER = 1.2  # curves at least this much faster than the reference show a rate effect
CLEARER = 4.0  # how much more one growth law must be contradicted than the other to be named
SOFTER = 3.0  # standard errors below a ratio of 1 that call a faster curve softer than the reference


@dataclass
class RateProfile:
    """F/F_ref at equal depth of one approach curve over the reference (slowest) curve, in depth bins."""

    curve: str
    speed_ratio: float  # v / v_ref
    depth: np.ndarray  # bin centres [m]
    ratio: np.ndarray

    @property
    def median(self) -> float:
        return float(np.median(self.ratio))

    @property
    def median_std(self) -> float:
        """Standard error of the median ratio from the bin-to-bin scatter: the median absolute second
        difference (blind to a smooth change with depth, robust to the steep first bins), at least 1e-4."""
        scatter = 1.4826 * float(np.median(np.abs(np.diff(self.ratio, 2)))) / np.sqrt(6.0)
        return max(1.2533 * scatter / np.sqrt(self.ratio.size), 1e-4)

    def ends(self) -> tuple[float, float]:
        """Median ratio over the shallowest and the deepest third of the bins."""
        third = max(self.ratio.size // 3, 1)
        return float(np.median(self.ratio[:third])), float(np.median(self.ratio[-third:]))


@dataclass
class RateEffect:
    reference: str
    profiles: list[RateProfile]

    def sentence(self) -> str:
        """The ratios over depth and how the excess grows with speed, in words a user can check."""
        ratios = "; ".join(
            f"{p.curve}/{self.reference} ({p.speed_ratio:.3g}× the speed) {p.ends()[0]:.3f} → {p.ends()[1]:.3f} "
            f"from {p.depth[0] * 1e6:.2f} to {p.depth[-1] * 1e6:.2f} µm"
            for p in self.profiles
        )
        text = f"Rate effect before any model, F/F_{self.reference} at equal depth: {ratios}."
        return text + " " + (self._softer() or self._growth())

    def _softer(self) -> str:
        """Faster curves softer than the reference beyond ``SOFTER`` standard errors of their median ratio: every
        rate force stiffens a faster curve at equal depth (a viscosity, a drag, Darcy flow, a relaxing or
        power-law solid alike), so such curves differ by more than rate (real agarose, one spot's 15 µm/s curve
        at 0.71–0.83 of another's 5 µm/s one), and how the excess grows with speed reads nothing; '' where none
        is."""
        softer = [p for p in self.profiles if p.median + SOFTER * p.median_std < 1.0]
        if not softer:
            return ""
        listing = ", ".join(f"{p.curve} {p.median:.3f} ± {p.median_std:.3f}" for p in softer)
        return (
            f"Faster yet softer than {self.reference} (median F/F_{self.reference}): {listing}. A rate force only "
            "stiffens a faster curve, so these curves differ by more than rate, in their spots' stiffness or in "
            "their contacts, and how the excess grows with speed is not read."
        )

    def _growth(self) -> str:
        """How the excess grows with speed: a power law keeps ln r / ln(v/v_ref) (its alpha) the same at
        every speed, a viscous or Darcy force keeps (r − 1)/(v/v_ref − 1) the same. Said only where one
        of them changes with speed by over 3 standard errors and ``CLEARER`` times more than the other."""
        speeds = {round(p.speed_ratio, 3): p for p in self.profiles}
        if len(speeds) < 2:
            return "One speed ratio cannot show how the excess grows with speed (a third speed would)."
        profiles = list(speeds.values())
        exponent = [
            (np.log(p.median) / np.log(p.speed_ratio), p.median_std / p.median / np.log(p.speed_ratio))
            for p in profiles
        ]
        linear = [((p.median - 1) / (p.speed_ratio - 1), p.median_std / (p.speed_ratio - 1)) for p in profiles]
        spread = {name: _inconsistency(values) for name, values in (("power", exponent), ("linear", linear))}
        listing = (
            "ln r / ln(v/v_ref) (a power law's alpha, the same at every speed for one): "
            + ", ".join(f"{value:.3f}" for value, _ in exponent)
            + "; (r − 1)/(v/v_ref − 1) (the same at every speed for a viscous or Darcy force): "
            + ", ".join(f"{value:.3f}" for value, _ in linear)
        )
        if spread["linear"] > max(3.0, CLEARER * spread["power"]):
            verdict = (
                "the excess grows more slowly than linearly with speed, as a power law's does (or a lagging "
                "force's that saturates), not as a Darcy or viscous force's alone"
            )
        elif spread["power"] > max(3.0, CLEARER * spread["linear"]):
            verdict = "the excess grows linearly with speed, as a Darcy or viscous force's does, not as a power law's"
        else:
            verdict = "the scatter of the ratios cannot tell a power law's growth from a linear one"
        return f"Growth with speed: {listing}; {verdict}."


def _inconsistency(values: list[tuple[float, float]]) -> float:
    """The largest difference between two of the values in units of its standard error."""
    return max(abs(a - b) / np.hypot(sa, sb) for i, (a, sa) in enumerate(values) for b, sb in values[i + 1 :])


def rate_effect(curves: list[CurveKinematics], reference: CurveKinematics) -> RateEffect | None:
    """F/F_ref at equal depth of every approach faster than the reference by ``FASTER``, on depth bins
    common to all (where the slow force exceeds ``RATIO_FLOOR`` noise std, to the shallowest curve's
    deepest sample, so every ratio is read at the same depths); None where no curve gives a ratio."""
    faster = [c for c in curves if c is not reference and c.base_speed >= FASTER * reference.base_speed]
    approaches = {c.curve: _approach(c) for c in [reference, *faster]}
    if not faster or any(depth.size == 0 for depth, _ in approaches.values()):
        return None
    ref_depth, ref_force = approaches[reference.curve]
    strong = ref_depth[ref_force > RATIO_FLOOR * reference.noise.std]
    if strong.size == 0:
        return None
    edges = np.linspace(strong.min(), min(depth.max() for depth, _ in approaches.values()), RATIO_BINS + 1)
    if edges[-1] <= edges[0]:
        return None
    slow = _binned(*approaches[reference.curve], edges)
    profiles = []
    for curve in faster:
        fast = _binned(*approaches[curve.curve], edges)
        known = np.isfinite(fast) & np.isfinite(slow) & (slow > 0) & (fast > 0)
        if known.sum() >= 5:
            centres = 0.5 * (edges[:-1] + edges[1:])
            ratio = curve.base_speed / reference.base_speed
            profiles.append(RateProfile(curve.curve, ratio, centres[known], fast[known] / slow[known]))
    return RateEffect(reference.curve, profiles) if profiles else None


def _approach(curve: CurveKinematics) -> tuple[np.ndarray, np.ndarray]:
    use = curve.in_contact & (curve.segment == APPROACH)
    return curve.depth[use], curve.force[use]


def _binned(depth: np.ndarray, force: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """The force at each bin's centre: a line fitted to the samples in the bin (nan with fewer than 3)."""
    values = np.full(edges.size - 1, np.nan)
    for i, (low, high) in enumerate(zip(edges[:-1], edges[1:])):
        inside = (depth >= low) & (depth < high)
        if inside.sum() >= 3:
            values[i] = np.polyfit(depth[inside] - 0.5 * (low + high), force[inside], 1)[1]
    return values
