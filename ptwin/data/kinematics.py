"""Model quantities of each sample: depth w, contact radius R, velocity U, height H.

- ``w = z − F/k_s``; ``R = sqrt(ρ² − (ρ − w)²)`` (0 before contact); ``H = H0 − w``.
- ``U = dw/dt`` by local linear regression over a centred window of ``smoothing``
  (fraction of the approach's samples, ≈5%): a raw finite difference (paper eq. 7) turns
  force noise σ/k_s into a velocity noise ~σ/(k_s Δt) that invents rate effects. Windows
  stay within a segment (approach, hold, retract), so the ramp/hold corner is not smeared;
  still, the tip's stop at the corner is faster than a window, so the first half-window of
  a hold is left out of the fits (its velocity is not resolved), counted in ``settling``.
- Fits use the approach and the hold; a retract is kept but left out (adhesion and
  unloading are not in the vocabulary).
- The noise of each curve (``ptwin.data.noise``): measured on its pre-contact baseline
  where there is one, else from second differences.
- Known contact (``contact_point: known``): the pre-contact baseline offset (mean force at
  z < 0, e.g. cantilever drag) is measured and kept, never subtracted: it is evidence.
- Estimated contact (``contact_point: estimate``): each curve's contact point is estimated
  and its baseline offset and tilt removed (``ptwin.data.contact``); z then counts from
  the estimate, which the fit refines (``ContactNuisance``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from ptwin.data.contact import Baseline, NoBaseline, estimate_baseline
from ptwin.data.noise import NoiseModel, curve_noise
from ptwin.data.recordings import SEGMENTS, RecordingError, RecordingSet


@dataclass
class CurveKinematics:
    """Per-sample arrays of one curve (SI units, float64, all samples kept)."""

    curve: str
    base_speed: float  # the approach's base speed [m/s]: the curve's nominal speed
    time: np.ndarray  # [s]
    z: np.ndarray  # base displacement [m]
    force: np.ndarray  # measured force [N]
    depth: np.ndarray  # w [m]
    contact_radius: np.ndarray  # R [m]
    velocity: np.ndarray  # U [m/s]
    height: np.ndarray  # H [m]
    in_contact: np.ndarray  # bool: samples used in fits (z ≥ 0 and w > 0, not on a retract nor settling)
    segment: np.ndarray  # int: index into SEGMENTS (0 approach, 1 hold, 2 retract)
    base_speeds: np.ndarray  # each sample's base speed [m/s] (0 in a hold)
    noise: NoiseModel
    baseline_offset: float | None  # pre-contact force [N]: its mean (known contact), the removed line's at
    # contact (estimated contact), None without pre-contact samples
    baseline: Baseline | None  # the estimated contact and removed baseline (contact_point: estimate)
    settling: int = 0  # samples at the start of holds left out of fits (velocity not resolved there)

    @property
    def noise_floor(self) -> float:
        """σ of the curve's force noise [N]."""
        return self.noise.std


def contact_radius(depth, probe_radius: float):
    """R = sqrt(ρ² − (ρ − w)²) for 0 ≤ w ≤ ρ, and 0 for w < 0; an array or one float (ufuncs only: the
    simulator calls it on one depth thousands of times a curve)."""
    w = np.minimum(np.maximum(depth, 0.0), probe_radius)
    return np.sqrt(probe_radius**2 - (probe_radius - w) ** 2)


def window_line(x: np.ndarray, y: np.ndarray, lo: np.ndarray, hi: np.ndarray, at: np.ndarray):
    """Least-squares lines through samples lo[i]..hi[i] (inclusive) of sorted x:
    (value at ``at[i]``, slope) for every window i. O(N + windows), by cumulative sums."""
    shifted = x - x[0]

    def window_sum(values):
        cumulative = np.concatenate([[0.0], np.cumsum(values)])
        return cumulative[hi + 1] - cumulative[lo]

    count = (hi - lo + 1).astype(float)
    sx, sy, sxx, sxy = window_sum(shifted), window_sum(y), window_sum(shifted * shifted), window_sum(shifted * y)
    slope = (sxy - sx * sy / count) / (sxx - sx * sx / count)
    value = sy / count + slope * (at - x[0] - sx / count)
    return value, slope


def segmented_derivative(time: np.ndarray, values: np.ndarray, window: int, segment: np.ndarray) -> np.ndarray:
    """``smoothed_derivative`` within each run of equal ``segment`` codes, never across two."""
    result = np.empty_like(values)
    edges = np.flatnonzero(np.r_[True, segment[1:] != segment[:-1], True])
    for lo, hi in zip(edges[:-1], edges[1:]):
        if hi - lo >= 2:
            result[lo:hi] = smoothed_derivative(time[lo:hi], values[lo:hi], window)
        else:
            result[lo:hi] = 0.0  # one sample alone in its segment has no slope of its own
    return result


def smoothed_derivative(time: np.ndarray, values: np.ndarray, window: int) -> np.ndarray:
    """Slope of a least-squares line over a centred window of ``window`` samples.

    Works on non-uniform time; the window shrinks (stays centred where possible) at
    the ends.
    """
    n = len(values)
    index = np.arange(n)
    half = max(1, window // 2)
    lo, hi = np.clip(index - half, 0, n - 1), np.clip(index + half, 0, n - 1)
    return window_line(time, values, lo, hi, time)[1]


def curve_kinematics(recordings: RecordingSet, smoothing: float = 0.05, block: int = 50) -> list[CurveKinematics]:
    """Kinematics of every curve of a recording set, in file order; ``block``: the block length [samples]
    of the noise model's variance inflation (the whiteness test's)."""
    meta = recordings.meta
    result = []
    for curve_id in recordings.curve_ids:
        rows: pd.DataFrame = recordings.curve(curve_id)
        time, z, force = (rows[c].to_numpy(dtype=np.float64) for c in ("time", "z", "force"))
        segment = _segment_codes(rows)
        approach = segment == 0
        baseline = None
        if meta.contact_point == "estimate":
            baseline = _estimated_baseline(recordings, curve_id, z[approach], force[approach])
            z, force = baseline.remove(z, force)
        depth = z - force / meta.spring_constant
        window = max(5, int(round(smoothing * approach.sum())))  # the approach's: a long hold would widen it
        pre_contact = (z < 0) & approach
        noise = curve_noise(time, z, force, approach & (z <= 0.25 * min(z[0], 0.0)), block)
        if meta.noise_std:
            noise = replace(noise, std=meta.noise_std, source=f"noise_std of meta.yaml; correlation: {noise.source}")
        offset = baseline.offset if baseline else (float(force[pre_contact].mean()) if pre_contact.any() else None)
        speeds = rows["base_speed"].to_numpy(dtype=np.float64)
        settling = _settling(segment, window // 2)
        result.append(
            CurveKinematics(
                curve=curve_id,
                base_speed=float(speeds[approach][0]) if approach.any() else float(np.abs(speeds).max()),
                time=time,
                z=z,
                force=force,
                depth=depth,
                contact_radius=contact_radius(depth, meta.probe_radius),
                velocity=segmented_derivative(time, depth, window, segment),
                height=meta.sample_thickness - depth,
                in_contact=(z >= 0) & (depth > 0) & (segment < SEGMENTS.index("retract")) & ~settling,
                segment=segment,
                base_speeds=speeds,
                noise=noise,
                baseline_offset=offset,
                baseline=baseline,
                settling=int(settling.sum()),
            )
        )
    return result


def _settling(segment: np.ndarray, samples: int) -> np.ndarray:
    """The first ``samples`` of every hold."""
    hold = segment == SEGMENTS.index("hold")
    starts = np.flatnonzero(hold & ~np.r_[False, hold[:-1]])
    settling = np.zeros_like(hold)
    for start in starts:
        settling[start : start + samples] = True
    return settling & hold


def _segment_codes(rows: pd.DataFrame) -> np.ndarray:
    if "segment" not in rows:
        return np.zeros(len(rows), dtype=np.int64)
    return rows["segment"].map(SEGMENTS.index).to_numpy(dtype=np.int64)


def _estimated_baseline(recordings: RecordingSet, curve_id: str, z: np.ndarray, force: np.ndarray) -> Baseline:
    try:
        return estimate_baseline(z, force, recordings.meta.spring_constant)
    except NoBaseline as error:
        raise RecordingError(
            f"{recordings.path / 'curves.csv'}: curve {curve_id!r}: no baseline to estimate its contact point from "
            f"({error}); record the approach from further away, or give z from the contact and contact_point: known"
        ) from None
