"""Evidence the curves give before any model: what replicates say about spot-to-spot
variation, and what removed baselines say about drag. Sentences for the report, and
the numbers behind them."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from ptwin.data.kinematics import CurveKinematics

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
    """What the removed baseline offsets say about drag on the cantilever (offset = a + b·speed): a slope
    needs at least 4 curves at 3 speeds to be told from offsets that differ from curve to curve; with
    fewer, the offsets are listed. None when no baseline was removed."""
    removed = [c for c in curves if c.baseline is not None]
    speeds = np.array([c.base_speed for c in removed])
    if not removed:
        return None
    if len(removed) < 4 or np.unique(speeds).size < 3:
        listing = ", ".join(f"{c.curve} {c.baseline.offset * 1e9:.3g} nN" for c in removed)
        return f"Removed baseline offsets: {listing} (too few curves and speeds to tell drag from offset scatter)."
    offsets = np.array([c.baseline.offset for c in removed])
    design = np.column_stack([np.ones_like(speeds), speeds])
    (intercept, slope), residual, *_ = np.linalg.lstsq(design, offsets, rcond=None)
    scatter = float(np.sum((offsets - design @ [intercept, slope]) ** 2)) / max(len(removed) - 2, 1)
    std = float(np.sqrt(scatter * np.linalg.inv(design.T @ design)[1, 1]))
    if std > 0 and abs(slope) > 3 * std:
        return (
            f"The removed baseline offsets grow with speed by {slope:.2g} ± {std:.1g} N s/m: drag on the cantilever "
            f"(cantilever_drag), removed with the baselines."
        )
    return (
        f"The removed baseline offsets do not depend on speed (slope {slope:.2g} ± {std:.1g} N s/m): no sign of drag."
    )
