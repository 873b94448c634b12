"""Model quantities of each sample: depth w, contact radius R, velocity U, height H.

- ``w = z − F/k_s``; ``R = sqrt(ρ² − (ρ − w)²)`` (0 before contact); ``H = H0 − w``.
- ``U = dw/dt`` by local linear regression over a centred window of ``smoothing``
  (fraction of the curve's samples, ≈5%): a raw finite difference (paper eq. 7) turns
  force noise σ/k_s into a velocity noise ~σ/(k_s Δt) that invents rate effects.
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
from ptwin.data.recordings import RecordingError, RecordingSet


@dataclass
class CurveKinematics:
    """Per-sample arrays of one curve (SI units, float64, all samples kept)."""

    curve: str
    base_speed: float  # [m/s]
    time: np.ndarray  # [s]
    z: np.ndarray  # base displacement [m]
    force: np.ndarray  # measured force [N]
    depth: np.ndarray  # w [m]
    contact_radius: np.ndarray  # R [m]
    velocity: np.ndarray  # U [m/s]
    height: np.ndarray  # H [m]
    in_contact: np.ndarray  # bool: samples used in fits (z ≥ 0 and w > 0)
    noise: NoiseModel
    baseline_offset: float | None  # pre-contact force [N]: its mean (known contact), the removed line's at
    # contact (estimated contact), None without pre-contact samples
    baseline: Baseline | None  # the estimated contact and removed baseline (contact_point: estimate)

    @property
    def noise_floor(self) -> float:
        """σ of the curve's force noise [N]."""
        return self.noise.std


def contact_radius(depth: np.ndarray, probe_radius: float) -> np.ndarray:
    """R = sqrt(ρ² − (ρ − w)²) for 0 ≤ w ≤ ρ, and 0 for w < 0."""
    w = np.clip(depth, 0.0, probe_radius)
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
        baseline = None
        if meta.contact_point == "estimate":
            try:
                baseline = estimate_baseline(z, force, meta.spring_constant)
            except NoBaseline as error:
                raise RecordingError(
                    f"{recordings.path / 'curves.csv'}: curve {curve_id!r}: no baseline to estimate its contact "
                    f"point from ({error}); record the approach from further away, or give z from the contact "
                    f"and contact_point: known"
                ) from None
            z, force = baseline.remove(z, force)
        depth = z - force / meta.spring_constant
        window = max(5, int(round(smoothing * len(rows))))
        pre_contact = z < 0
        noise = curve_noise(time, z, force, z <= 0.25 * min(z[0], 0.0), block)
        if meta.noise_std:
            noise = replace(noise, std=meta.noise_std, source=f"noise_std of meta.yaml; correlation: {noise.source}")
        offset = baseline.offset if baseline else (float(force[pre_contact].mean()) if pre_contact.any() else None)
        result.append(
            CurveKinematics(
                curve=curve_id,
                base_speed=float(rows["base_speed"].iloc[0]),
                time=time,
                z=z,
                force=force,
                depth=depth,
                contact_radius=contact_radius(depth, meta.probe_radius),
                velocity=smoothed_derivative(time, depth, window),
                height=meta.sample_thickness - depth,
                in_contact=(~pre_contact) & (depth > 0),
                noise=noise,
                baseline_offset=offset,
                baseline=baseline,
            )
        )
    return result
