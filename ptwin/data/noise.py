"""The force noise of each curve, measured where the tip touches nothing.

A real cantilever's noise is correlated (thermal motion, 1/f, drift), so its std alone
overstates every statistic that averages residuals: a smooth misfit averages down as
σ²/n only for white noise. The model kept here is

- ``std`` σ [N] and the lag-1 autocorrelation φ (an AR(1) summary; ``correlation_time``
  τ = −Δt/ln φ, 0 when φ ≤ 0), and
- ``inflation`` κ²: the variance of means of ``block`` consecutive samples, in units of
  the white expectation σ²/block (1 for white noise, > 1 for correlated noise).

κ² is what the statistics use (whiteness ÷ κ², n/κ² effective samples in the information
criteria, parameter variances × κ²). It is the larger of the block variance measured
directly (it sees 1/f drift, but is noisy with few blocks) and the AR(1) prediction from
φ (precise from a few hundred samples, blind to drift), and never below 1: the noise
model never makes the data more informative than white noise would.

Where a curve has a pre-contact baseline of at least ``MIN_BASELINE`` samples, the noise
is what is left there after a straight line in z is removed (real-noise.md's recipe).
Otherwise the std comes from second differences (robust, exact for white noise under a
smooth signal) and the correlation of the other curves' baselines is used, if any.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MIN_BASELINE = 100  # samples of pre-contact baseline for a measured noise model
BASELINE = "pre-contact baseline"
SECOND_DIFFERENCES = "second differences of the curve (no baseline long enough)"


@dataclass(frozen=True)
class NoiseModel:
    """The noise of one curve, or of a whole recording set (``pooled``)."""

    std: float  # σ [N]
    lag1: float  # φ, lag-1 autocorrelation
    inflation: float  # κ² ≥ 1: block-mean variance over the white expectation
    correlation_time: float  # [s], 0 for white or anti-correlated noise
    source: str  # where it was measured
    samples: int  # how many samples it was measured on


def ar1_inflation(lag1: float, block: int) -> float:
    """κ² of AR(1) noise for means of ``block`` samples: 1 + 2 Σ_k (1 − k/B) φ^k."""
    k = np.arange(1, block)
    return float(1.0 + 2.0 * np.sum((1.0 - k / block) * lag1**k))


def block_inflation(noise: np.ndarray, block: int) -> float:
    """κ² measured: variance of the means of every ``block`` consecutive samples (overlapping
    windows, for a steadier estimate) times ``block``, over the variance."""
    if noise.size < 4 * block:
        return 1.0
    cumulative = np.concatenate([[0.0], np.cumsum(noise)])
    means = (cumulative[block:] - cumulative[:-block]) / block
    return float(block * np.mean(means**2) / np.mean(noise**2))


def correlation_time(lag1: float, step: float) -> float:
    """τ [s] of an AR(1) with lag-1 correlation φ at sampling step Δt: φ = exp(−Δt/τ)."""
    return -step / math.log(lag1) if 0.0 < lag1 < 1.0 else 0.0


def baseline_noise(time: np.ndarray, z: np.ndarray, force: np.ndarray, block: int) -> NoiseModel | None:
    """The noise model of a baseline (samples where the tip is free), or None if it is too short.

    A straight line force(z) is removed first: the baseline's offset and tilt are not noise.
    """
    if force.size < MIN_BASELINE:
        return None
    design = np.column_stack([np.ones_like(z), z - z.mean()])
    coefficients, *_ = np.linalg.lstsq(design, force, rcond=None)
    noise = force - design @ coefficients
    std = float(np.sqrt(np.mean(noise**2) * noise.size / (noise.size - 2)))
    if std == 0.0:
        return None
    lag1 = float(np.clip(np.mean(noise[1:] * noise[:-1]) / np.mean(noise**2), -0.99, 0.99))
    inflation = max(1.0, ar1_inflation(lag1, block), block_inflation(noise, block))
    step = float(np.median(np.diff(time)))
    return NoiseModel(std, lag1, inflation, correlation_time(lag1, step), BASELINE, int(force.size))


def second_difference_std(force: np.ndarray) -> float:
    """σ of white force noise from second differences (robust MAD): 1.4826·MAD/√6."""
    second = np.diff(force, 2)
    return float(1.4826 * np.median(np.abs(second - np.median(second))) / np.sqrt(6.0))


def curve_noise(time, z, force, baseline: np.ndarray, block: int) -> NoiseModel:
    """The noise of one curve: measured on its ``baseline`` samples (bool mask) if long enough,
    else σ from second differences of the whole curve, correlation unknown (κ² = 1 until pooled)."""
    measured = baseline_noise(time[baseline], z[baseline], force[baseline], block)
    if measured is not None:
        return measured
    return NoiseModel(second_difference_std(force), 0.0, 1.0, 0.0, SECOND_DIFFERENCES, int(force.size))


def pooled(models: list[NoiseModel], weights: list[float], steps: list[float]) -> NoiseModel:
    """The set's noise: σ averaged with ``weights`` (fitted samples per curve); correlation (φ, κ²) the
    median over the curves with a measured baseline (one instrument, one sample), else white."""
    std = float(np.average([m.std for m in models], weights=weights))
    measured = [m for m in models if m.source == BASELINE]
    if not measured:
        return NoiseModel(std, 0.0, 1.0, 0.0, SECOND_DIFFERENCES, sum(m.samples for m in models))
    lag1 = float(np.median([m.lag1 for m in measured]))
    inflation = float(np.median([m.inflation for m in measured]))
    return NoiseModel(
        std,
        lag1,
        inflation,
        correlation_time(lag1, float(np.median(steps))),
        BASELINE,
        sum(m.samples for m in measured),
    )
