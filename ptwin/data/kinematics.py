"""Model quantities of each sample: depth w, contact radius R, velocity U, height H.

- ``w = z − F/k_s``; ``R = sqrt(ρ² − (ρ − w)²)`` (0 before contact); ``H = H0 − w``.
- ``U = dw/dt`` by local linear regression over a centred window of ``smoothing``
  (fraction of the approach's samples, ≈5%): a raw finite difference (paper eq. 7) turns
  force noise σ/k_s into a velocity noise ~σ/(k_s Δt) that invents rate effects. Windows
  stay within a segment (approach, hold, retract) and on one side of the contact, growing from it as from a
  segment's start, so neither the ramp/hold corner nor the bend at contact is smeared
  (one-sided at a segment's ends: a window shrunk to a few samples there would carry that
  velocity noise into the Darcy force, several noise std at a fast curve's deepest samples).
  Every sample of a hold is fitted, its first milliseconds too (a pore pressure draining in
  5–20 ms is all there is to see there), but for the samples whose velocity the sampling
  cannot resolve (``unresolved_motion``): when a fast ramp stops, the cantilever
  relaxes in a millisecond or less, and the tip's velocity at the first samples of the hold
  is anywhere between the ramp's and a fraction of it, so the rate forces there are not fixed
  by the recording (at 45 µm/s on a soft cantilever, four such samples 30σ off pulled a fit's
  K by 17%). Those are left out of the fits.
- Fits use the approach and the hold; a retract is kept but left out (adhesion and
  unloading are not in the vocabulary).
- The noise of each curve (``ptwin.data.noise``): measured on its pre-contact baseline
  where there is one, else from second differences.
- Known contact (``contact_point: known``): the pre-contact baseline offset (mean force at
  z < 0, e.g. cantilever drag) is measured and kept, never subtracted: it is evidence.
- Estimated contact (``contact_point: estimate``): each curve's contact point is estimated
  and its baseline offset and tilt removed (``ptwin.data.contact``); z then counts from
  the estimate, which the fit refines (``ContactNuisance``). Where the curves' levels are one
  common level plus drag (b·speed within their standard errors), only the common level is
  removed: the drag stays in the force, as evidence. The last quarter of the free travel
  (``PINNING_TRAVEL``, at most one indentation deep) is fitted with the contact: the force
  must stay at the baseline there, which pins the refined contact (a contact moved earlier
  predicts force where there is none) and tells a contact shift from a term growing like √w.
  The noise is measured on the rest of the free travel, never on samples the fit sees.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
from numpy.lib.stride_tricks import sliding_window_view

from ptwin.data.contact import Baseline, NoBaseline, baseline_levels, drifted, estimate_baseline
from ptwin.data.noise import NoiseModel, curve_noise, robust_std, set_drift, with_std
from ptwin.data.recordings import APPROACH, RETRACT, SEGMENTS, Meta, RecordingError, RecordingSet
from ptwin.data.tails import normal_exceeded

PINNING_TRAVEL = 0.25  # the last fraction of an approach's free travel, fitted with an estimated contact
BENDING_WINDOW = 15  # samples a motion's bending is read over: a stop's few marked samples are outvoted in it
UNRESOLVED_FALSE_ALARM = 0.01  # samples of a curve that noise alone marks unresolved, expected
# A velocity window growing from the contact reaches at least 1/CONTACT_WINDOW of the full window either side (a
# fifth of it in all): a measured height's noise (real JPK heights scatter 0.1 nm against steps of 1 nm) puts 7% of
# the velocity into a line through three samples, 0.6% into one through 15 (a 75-sample window's fifth; a slope's
# std is σ·√(12/(n(n²−1))) per step), and the bend's bias barely grows (``segmented_derivative``; a √w bend in
# ``tests/test_kinematics.py``: 0.08% of the speed from three samples, 0.18% from 21).
CONTACT_WINDOW = 10


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
    in_contact: np.ndarray  # bool: samples in contact, fitted (z ≥ 0 and w > 0, not on a retract)
    segment: np.ndarray  # int: index into SEGMENTS (APPROACH, HOLD, CREEP, RETRACT)
    base_speeds: np.ndarray  # each sample's base speed [m/s] (0 in a hold)
    noise: NoiseModel
    baseline_offset: float | None  # pre-contact force [N]: its mean (known contact), the removed line's at
    # contact (estimated contact), None without pre-contact samples
    baseline: Baseline | None  # the estimated contact and removed baseline (contact_point: estimate)
    # bool: the pre-contact samples just before contact, fitted (not judged): they pin an estimated contact, and
    # with a known one they show what a rate force there would offset (a drag, b·v before any contact)
    pins_contact: np.ndarray | None = None
    unresolved: np.ndarray | None = None  # bool: samples whose velocity the sampling does not resolve

    def __post_init__(self):
        if self.pins_contact is None:
            self.pins_contact = np.zeros_like(self.in_contact)
        if self.unresolved is None:
            self.unresolved = np.zeros_like(self.in_contact)

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
    (value at ``at[i]``, slope) for every window i. O(N + windows), by cumulative sums. ``y`` (N, …)
    may carry trailing axes: one line per column."""
    shifted = x - x[0]
    column = (slice(None),) + (None,) * (y.ndim - 1)  # y may carry trailing axes (replicates): x's sums broadcast

    def window_sum(values):
        cumulative = np.concatenate([np.zeros((1, *values.shape[1:])), np.cumsum(values, axis=0)])
        return cumulative[hi + 1] - cumulative[lo]

    count = (hi - lo + 1).astype(float)[column]
    sx, sxx = window_sum(shifted)[column], window_sum(shifted * shifted)[column]
    sy, sxy = window_sum(y), window_sum(shifted[column] * y)
    slope = (sxy - sx * sy / count) / (sxx - sx * sx / count)
    value = sy / count + slope * ((at - x[0])[column] - sx / count)
    return value, slope


def segmented_derivative(
    time: np.ndarray, values: np.ndarray, window: int, segment: np.ndarray, touching: np.ndarray | None = None
) -> np.ndarray:
    """``smoothed_derivative`` within each run of equal ``segment`` codes, never across two; after the
    approach (a hold, a creep) and in contact with windows that grow with the time since the run began.
    ``touching`` (bool, optional): the samples from the contact point on, where the runs are split too (once: a
    recorded height whose noise crosses the contact back and forth would cut runs of a sample or two, whose
    slopes are noise or nil).

    At contact the tip's velocity bends as a segment's corner does: before it the tip moves with the base, after
    it the rate forces grow from zero (a viscosity's as √w, so steepest at contact) and hold it back. A window
    across the contact averaged the free travel into the first samples of contact: on a soft cantilever with 25
    Pa·s concealed (known contacts, white noise) K came out 6.0% high beside a contact offset named; split
    there, 2.1% with the viscosity alone. A full window just past the contact still averages the bend (there,
    noise-free, the fastest curve's velocity 3.8% high over its first tenth in contact, 5.7% across the contact;
    growing from a fifth of the window, 0.47%): with the contact estimated, that error moved the refined contact
    and K with it (real PAAm noise in the shared p05's setting, six seeds: K 2.6–6.1% higher with 25 Pa·s than
    without; growing, 1.0–4.4%)."""
    result = np.empty_like(values)
    runs = segment if touching is None else 2 * segment + touching
    edges = np.flatnonzero(np.r_[True, runs[1:] != runs[:-1], True])
    for lo, hi in zip(edges[:-1], edges[1:]):
        if hi - lo >= 2:
            after_corner = segment[lo] != APPROACH
            growing = after_corner or (touching is not None and bool(touching[lo]))
            least = 1 if after_corner else max(1, window // CONTACT_WINDOW)
            result[lo:hi] = smoothed_derivative(time[lo:hi], values[lo:hi], window, growing, least)
        else:
            result[lo:hi] = 0.0  # one sample alone in its segment has no slope of its own
    return result


def smoothed_derivative(
    time: np.ndarray, values: np.ndarray, window: int, growing: bool = False, least: int = 1
) -> np.ndarray:
    """Slope of a least-squares line over a centred window of ``window`` samples.

    Works on non-uniform time; the window shrinks (stays centred where possible) at
    the ends. ``growing``: sample j's window reaches at most j/2 samples either side (``least`` at the
    fewest), so it widens with the time since the first sample (a relaxation is read on a log time axis):
    when the base stops, the tip keeps moving for a millisecond or so while the cantilever
    relaxes (τ = F_D/U over k_s + dF_el/dw), and a full window there smeared that motion, and
    the Darcy force it carries, over tens of milliseconds.
    """
    n = len(values)
    index = np.arange(n)
    half = np.full(n, max(1, window // 2))
    if growing:
        half = np.clip(index // 2, least, half)
    lo, hi = np.clip(index - half, 0, n - 1), np.clip(index + half, 0, n - 1)
    return window_line(time, values, lo, hi, time)[1]


def unresolved_motion(time: np.ndarray, depth: np.ndarray, tested: np.ndarray) -> np.ndarray:
    """Samples (of ``tested``, time-ordered) where the tip's velocity changes within the sampling by more
    than noise explains: the second divided difference of w at each sample, in units of what white noise on
    w gives it (sampling rates may differ between segments), beyond what noise alone exceeds
    ``UNRESOLVED_FALSE_ALARM`` times a curve. The noise's scale is the median absolute deviation over the
    curve (robust to the few samples looked for; it carries the force's noise through w = z − F/k_s and the
    base's own), so Gaussian noise marks a sample with probability ``UNRESOLVED_FALSE_ALARM``/N at most; a marked
    sample must stand out of its neighbours' running median by as much (``BENDING_WINDOW``). At such a
    sample the instantaneous velocity, and the rate force on it, lies anywhere between the one-sided slopes
    on either side."""
    index = np.flatnonzero(tested)
    unresolved = np.zeros_like(tested)
    if index.size < 5:
        return unresolved
    w = depth[index]
    before, after = np.diff(time[index])[:-1], np.diff(time[index])[1:]
    inner = (before > 0) & (after > 0)
    before, after = np.where(inner, before, 1.0), np.where(inner, after, 1.0)
    # w_{j−1}, w_j, w_{j+1} weighted as the divided difference weighs them, scaled to unit norm
    weights = np.stack([1 / (before * (before + after)), -1 / (before * after), 1 / (after * (before + after))])
    weights /= np.sqrt((weights**2).sum(axis=0))
    scaled = np.where(inner, (weights * np.stack([w[:-2], w[1:-1], w[2:]])).sum(axis=0), 0.0)
    typical = robust_std(scaled[inner])
    if not typical > 0:
        return unresolved
    limit = normal_exceeded(UNRESOLVED_FALSE_ALARM / (2 * inner.sum())) * typical
    # A resolved motion bends smoothly (w as the force builds up), which outgrew the noise on a quiet recording (σ
    # 3e-15 N on a soft cantilever: every sample in contact marked, 87 of 272 fitted); a stop's few samples stand
    # out of the running median. The second condition only unmarks: noise alone marks no more than before.
    half = BENDING_WINDOW // 2
    bending = np.median(sliding_window_view(np.pad(scaled, half, mode="edge"), BENDING_WINDOW), axis=1)
    unresolved[index[1:-1]] = inner & (np.abs(scaled) > limit) & (np.abs(scaled - bending) > limit)
    return unresolved


def curve_kinematics(recordings: RecordingSet, smoothing: float = 0.05, block: int = 50) -> list[CurveKinematics]:
    """Kinematics of every curve of a recording set, in file order; ``block``: the block length [samples]
    of the noise model's variance inflation (the whiteness test's)."""
    meta = recordings.meta
    rows = {curve_id: recordings.curve(curve_id) for curve_id in recordings.curve_ids}
    baselines, speeds = _estimated_baselines(recordings, rows) if meta.contact_point == "estimate" else ({}, [])
    # A baseline's noise is read with its own line removed, whichever level the set's removes.
    noises = {curve_id: _curve_noise(curve, baselines.get(curve_id), meta, block) for curve_id, curve in rows.items()}
    if baselines:
        baselines = _levels_removed(baselines, speeds, noises, rows, block)
    result = []
    for curve_id, curve in rows.items():
        baseline = baselines.get(curve_id)
        time, z, force, segment = _arrays(curve, baseline)
        approach = segment == APPROACH
        depth = z - force / meta.spring_constant
        window = max(5, int(round(smoothing * approach.sum())))  # the approach's: a long hold would widen it
        # The velocity bends at the contact. Estimated, the Hertz onset puts it early wherever a force grows as
        # √w (44–88 samples on a soft cantilever with 25 Pa·s), the onset read as Hertz beside a √w force within
        # 2 samples (10–15 late without such a force, where the bend is mild): the runs split there. (Known, z
        # counts from the contact and there is no baseline; estimated, every curve has one.)
        touching = np.maximum.accumulate(z >= (0.0 if baseline is None else baseline.root_shift))
        pre_contact = (z < 0) & approach
        noise = noises[curve_id]
        offset = baseline.offset if baseline else (float(force[pre_contact].mean()) if pre_contact.any() else None)
        speeds = curve["base_speed"].to_numpy(dtype=np.float64)
        result.append(
            CurveKinematics(
                curve=curve_id,
                base_speed=float(speeds[approach][0]) if approach.any() else float(np.abs(speeds).max()),
                time=time,
                z=z,
                force=force,
                depth=depth,
                contact_radius=contact_radius(depth, meta.probe_radius),
                velocity=segmented_derivative(time, depth, window, segment, touching),
                height=meta.sample_thickness - depth,
                in_contact=(z >= 0) & (depth > 0) & (segment != RETRACT),
                segment=segment,
                base_speeds=speeds,
                noise=noise,
                baseline_offset=offset,
                baseline=baseline,
                pins_contact=pre_contact & ~_free(z, segment) & (z >= -depth.max()),
                # A noise-free curve (a simulation's) gives no scale to judge by: nothing is left out.
                unresolved=unresolved_motion(time, depth, segment != RETRACT) if noise.std > 0 else None,
            )
        )
    return result


def _arrays(curve: pd.DataFrame, baseline: Baseline | None) -> tuple[np.ndarray, ...]:
    """(time [s], z [m], force [N], segment codes) of a curve's rows, ``baseline`` removed where there is one."""
    time, z, force = (curve[c].to_numpy(dtype=np.float64) for c in ("time", "z", "force"))
    if baseline is not None:
        z, force = baseline.remove(z, force)
    return time, z, force, _segment_codes(curve)


def _free(z: np.ndarray, segment: np.ndarray) -> np.ndarray:
    """The approach's free travel whose noise is read: all but its last ``PINNING_TRAVEL``, which pins a contact."""
    return (segment == APPROACH) & (z <= PINNING_TRAVEL * min(z[0], 0.0))


def _curve_noise(curve: pd.DataFrame, baseline: Baseline | None, meta: Meta, block: int) -> NoiseModel:
    """A curve's noise model, read on its free travel (``_free``), its σ the one meta.yaml gives where it does."""
    time, z, force, segment = _arrays(curve, baseline)
    noise = curve_noise(time, z, force, _free(z, segment), block)
    if baseline is not None and noise.slope is not None:  # the set's drift reads slopes as recorded
        noise = replace(noise, slope=replace(noise.slope, value=noise.slope.value + baseline.tilt))
    if meta.noise_std:
        noise = with_std(noise, meta.noise_std, "noise_std of meta.yaml")
    return noise


def _segment_codes(rows: pd.DataFrame) -> np.ndarray:
    if "segment" not in rows:
        return np.zeros(len(rows), dtype=np.int64)
    return rows["segment"].map(SEGMENTS.index).to_numpy(dtype=np.int64)


def _estimated_baselines(
    recordings: RecordingSet, rows: dict[str, pd.DataFrame]
) -> tuple[dict[str, Baseline], list[float]]:
    """Each curve's estimated contact and baseline, its own level removed, and its approach's base speed [m/s]."""
    baselines, speeds = {}, []
    for curve_id, curve in rows.items():
        approach = _segment_codes(curve) == APPROACH
        z, force = (curve[c].to_numpy(dtype=np.float64)[approach] for c in ("z", "force"))
        baselines[curve_id] = _estimated_baseline(recordings, curve_id, z, force)
        speeds.append(float(curve["base_speed"].to_numpy()[approach][0]))
    return baselines, speeds


def _levels_removed(
    baselines: dict[str, Baseline],
    speeds: list[float],
    noises: dict[str, NoiseModel],
    rows: dict[str, pd.DataFrame],
    block: int,
) -> dict[str, Baseline]:
    """``baselines`` (their curves' approaches at ``speeds`` [m/s]) with the level each curve has removed: only the
    set's common one where the levels are one common level plus drag that rises with speed beyond their scatter
    (``LevelsWithSpeed.shows_drag``), so that the drag stays in the force; else each curve's own. Each level's error
    is its baseline's noise and the drift the set's baseline slopes show, whether or not noise alone could give it
    (``Drift.estimate``, ``ptwin.data.contact.drifted``): on p06's setting with a drag and the public cell records'
    noise, the levels were one level plus drag at 4 of 12 seeds read without it, at 10 of 12 with it; the same sets
    without the drag were taken for drag at 1 of 12 without it and at none with it (``LevelsWithSpeed.shows_drag``)."""
    models = list(noises.values())
    steps = [float(np.median(np.diff(curve["time"].to_numpy(dtype=np.float64)))) for curve in rows.values()]
    found = set_drift(models, steps, block)
    if found is not None and found.estimate > 0.0:
        baselines = {c: drifted(b, found.estimate * noises[c].std ** 2, found.memory) for c, b in baselines.items()}
    fit = baseline_levels(list(baselines.values()), speeds)
    if fit is None or not fit.shows_drag:
        return baselines
    return {curve_id: b.with_offset(fit.common) for curve_id, b in baselines.items()}


def _estimated_baseline(recordings: RecordingSet, curve_id: str, z: np.ndarray, force: np.ndarray) -> Baseline:
    try:
        return estimate_baseline(z, force, recordings.meta.spring_constant)
    except NoBaseline as error:
        raise RecordingError(
            f"{recordings.path / 'curves.csv'}: curve {curve_id!r}: no baseline to estimate its contact point from "
            f"({error}); record the approach from further away, or give z from the contact and contact_point: known"
        ) from None
