"""The force noise of each curve, measured where the tip touches nothing.

A real cantilever's noise is correlated (thermal motion, 1/f, drift), so its std alone
overstates every statistic that averages residuals: a smooth misfit averages down as
σ²/n only for white noise. The model kept here is white noise plus an AR(1) part,

    ρ_k = c · φ^k   (k ≥ 1; c the AR part's share of the variance, φ its memory),

which is what real AFM noise looks like at the lags that matter (real-noise.md: a white
floor under thermal correlation), with

- ``std`` σ [N], ``lag1`` ρ₁ = cφ, ``correlation_time`` τ = −Δt/ln φ (0 for white), and
- ``inflation`` κ²: the variance of means of ``block`` consecutive samples, in units of
  the white expectation σ²/block (1 for white noise, > 1 for correlated noise).

κ² is what the statistics use (whiteness ÷ κ², n/κ² effective samples in the information
criteria, parameter variances × κ²). It is the larger of the model's prediction and the
block variance measured directly where a baseline holds four blocks (that sees 1/f drift
the AR(1) part cannot), and never below 1: the noise model never makes the data more
informative than white noise would.

Where a curve has a pre-contact baseline of at least ``MIN_BASELINE`` samples, the noise
is what is left there after a straight line in z is removed (real-noise.md's recipe), from
where the baseline has settled (``settled``: an approach can start ringing).
Removing the line biases a short record's autocorrelation low (a 116-sample baseline of
20-sample correlation loses most of it), so (c, φ) are fitted to the *expected* sample
autocorrelation of a detrended record of each length, computed exactly, and the set's
correlation is fitted on every curve's baseline at once (``pooled``). Without a baseline
σ comes from second differences, corrected for the set's correlation where it is known;
a baseline too short for a model of its own (``MIN_RECORD`` to ``MIN_BASELINE`` samples) still
adds its detrended record to the set's correlation (halving a set's sampling rate, or a
third off its baselines, turned correlated-noise nulls white and into false alarms).
A ``noise_std`` a lab wrote down replaces σ only: the correlation is still measured.

``blocks`` ν counts the independent block means κ² rests on (baseline samples / block):
the whiteness test's null distribution depends on it (``ptwin.diagnosis.locate``).

A baseline is a few hundred samples, and the line removed from it hides whatever drifts over
longer spans: the drift of real cell noise bends each curve by a slope of its own, which a
detrended baseline reads as white (real-noise.md: cells' block variance grows with the window).
The set's baselines see it together: their slopes (before any line was removed) are the
instrument's tilt in z and the drag's gradient, a line in the speed, plus each curve's noise: χ²
on n − 2 degrees of freedom under the model (n − 1 at one speed); beyond its (1 − false alarm)
quantile they hold a drift the model lacks (``Drift``), added to the noise the tests simulate as
an AR(1) part of the baselines' own length, the longest span they measured, of the variance that
makes the slopes' expected scatter their χ².
"""

from __future__ import annotations

import functools
import math
from dataclasses import asdict, dataclass, field, fields, replace

import numpy as np
import scipy.fft

from ptwin.data.tails import chi_square_exceeded

MIN_BASELINE = 100  # samples of pre-contact baseline for a curve's own measured noise model
RINGING = 2.0  # a baseline rings where its first block has this many times the variance of any settled one
LEVEL_SHIFT = 3.0  # a baseline starts off its level where its first block's mean departs 3× any settled one's
MIN_RECORD = 30  # samples of a shorter baseline that still add to the set's pooled correlation
BASELINE = "pre-contact baseline"
SHORT_BASELINES = "pre-contact baselines, each shorter than 100 samples, pooled"
SECOND_DIFFERENCES = "second differences of the curve (no baseline long enough)"
NOTHING = "nothing: "  # the source of a noise model with no noise to read (σ 0): a fit cannot be judged by it
SILENT = NOTHING + "the baseline before contact is flat to rounding"
STUCK = NOTHING + "half its second differences or more are zero (read for its noise: its baseline is too short)"
# A baseline whose scatter about its line is this fraction of its curve's force range or less holds rounding, not
# noise (a simulation without noise, a force smoothed or exported to few digits): far below any instrument's
# resolution (a 16–24-bit converter's step is 1e-5–1e-7 of its range), and no correlation can be fitted to it.
ROUNDING = 1e-9
RESIDUAL = "hybrid twin's residual in contact (no baseline of 100 samples)"
_MEMORIES = np.exp(-1.0 / np.geomspace(0.3, 300.0, 48))  # φ grid: correlation times 0.3–300 samples
_SHARES = np.linspace(-0.5, 1.0, 61)  # c grid (anti-correlated cell noise has c·φ < 0)


@dataclass(frozen=True)
class BaselineSlope:
    """A curve's baseline slope as recorded: dF/dz [N/m] of the samples its noise was read on (a line removed
    before added back), their spacing in z [m], the probe's speed there [m/s] and their own σ about the line [N]
    (``scatter``: what the slope's error follows, where a σ given elsewhere replaces the model's)."""

    value: float
    step: float
    speed: float
    scatter: float


@dataclass(frozen=True)
class Drift:
    """The set's baseline slopes about their line in the speed (``drift``): ``chi_square`` on ``dof`` degrees of
    freedom under the noise model. Beyond what noise alone exceeds one time in 1/false alarm, the drift the model
    lacks: an AR(1) part of memory φ ``memory`` per sample (``correlation_time`` [s]), the baselines' median
    length, and variance ``share``·σ², which makes the slopes' expected χ² what they read; else ``share`` is 0."""

    chi_square: float
    dof: int
    share: float
    memory: float
    correlation_time: float
    # the variance the slopes' scatter gives, beyond noise or not (at least 0): what a level read over the same
    # span is widened by (``ptwin.data.contact.drifted``), where a drift that noise alone could give is no reason
    # to take the levels' scatter for offsets
    estimate: float = 0.0


@dataclass(frozen=True)
class NoiseModel:
    """The noise of one curve, or of a whole recording set (``pooled``)."""

    std: float  # σ [N]
    lag1: float  # ρ₁ = c·φ, lag-1 autocorrelation
    inflation: float  # κ² ≥ 1: block-mean variance over the white expectation
    correlation_time: float  # [s] of the AR(1) part, 0 for white noise
    source: str  # where it was measured
    samples: int  # how many samples it was measured on
    share: float = 0.0  # c: the AR(1) part's share of the variance
    memory: float = 0.0  # φ: the AR(1) part's lag-1 correlation
    blocks: float = math.inf  # ν: independent block means the correlation rests on (inf: assumed white)
    longest: int = 0  # samples of the longest record the correlation was read on: it sees no slower noise (0: none)
    record: np.ndarray | None = field(default=None, compare=False, repr=False)  # the detrended baseline [N]
    short: np.ndarray | None = field(default=None, compare=False, repr=False)  # a baseline too short for a model
    unsettled: int = 0  # samples at the start of the baselines left out: not settled (``settled``, ``level_settled``)
    # σ read off second differences as if the noise were white [N], where ``std`` is it corrected for the set's
    # correlation (``corrected``); None where σ was measured otherwise
    differences: float | None = None
    slope: BaselineSlope | None = None  # a curve's: its baseline's slope as recorded (``Drift``)
    drift: Drift | None = None  # a set's: what its baselines' slopes say of the noise beyond their length

    def as_dict(self) -> dict:
        """Every number of the model (results.json), without the baseline record."""
        skipped = ("record", "short", "differences", "slope", "drift")
        numbers = {f.name: getattr(self, f.name) for f in fields(self) if f.name not in skipped}
        return {**numbers, "drift": None if self.drift is None else asdict(self.drift)}

    def autocorrelation(self, lags: np.ndarray) -> np.ndarray:
        """ρ_k of the model at ``lags`` (ρ₀ = 1)."""
        lags = np.asarray(lags)
        return np.where(lags == 0, 1.0, self.share * self.memory ** np.abs(lags))


def model_inflation(share: float, memory: float, block: int) -> float:
    """κ² of white + AR(1) noise (ρ_k = c·φ^k) for means of ``block`` samples: 1 + 2c Σ_k (1 − k/B) φ^k."""
    k = np.arange(1, block)
    return float(1.0 + 2.0 * share * np.sum((1.0 - k / block) * memory**k))


def mean_inflation(share: float, memory: float) -> float:
    """κ² of white + AR(1) noise for the mean of a record far longer than its memory, ``model_inflation``'s limit
    (1 − c) + c(1 + φ)/(1 − φ), never below 1: how many samples one independent sample's worth of it spans."""
    return max(1.0, (1.0 - share) + share * (1.0 + memory) / (1.0 - memory))


def ar1_inflation(lag1: float, block: int) -> float:
    """κ² of pure AR(1) noise (c = 1, φ = ``lag1``)."""
    return model_inflation(1.0, lag1, block)


def block_inflation(noise: np.ndarray, block: int) -> float | None:
    """κ² measured: variance of the means of every ``block`` consecutive samples (overlapping windows,
    for a steadier estimate) times ``block``, over the variance; None on fewer than four blocks."""
    if noise.size < 4 * block:
        return None
    cumulative = np.concatenate([[0.0], np.cumsum(noise)])
    means = (cumulative[block:] - cumulative[:-block]) / block
    return float(block * np.mean(means**2) / np.mean(noise**2))


def correlation_time(memory: float, step: float) -> float:
    """τ [s] of an AR(1) with lag-1 correlation φ at sampling step Δt: φ = exp(−Δt/τ)."""
    return -step / math.log(memory) if 0.0 < memory < 1.0 else 0.0


def autoregressive(inputs: np.ndarray, memory, gain: float = 1.0, before=None) -> np.ndarray:
    """y_t = gain·x_t + φ·y_{t−1} along the first axis of ``inputs`` x, from y_{−1} = ``before`` (0 where None);
    ``memory`` φ, one or an array broadcasting against a row of x (a filter per φ). It is
    ``scipy.signal.lfilter([gain], [1, −φ], x, axis=0, zi=φ·before)`` to the bit, a row at a time in place (one
    record in Python floats): importing scipy.signal costs 0.9 s beside torch, more than a run's filtering."""
    rows = np.broadcast_shapes(inputs.shape[1:], np.shape(memory))
    outputs = np.broadcast_to(gain * inputs, inputs.shape[:1] + rows).copy()  # gain·x_t, then φ·y_{t−1} added
    memory = np.broadcast_to(memory, rows).reshape(-1)
    carried = memory * (0.0 if before is None else np.broadcast_to(before, rows).reshape(-1))
    columns = outputs.reshape(len(outputs), math.prod(rows))
    if columns.shape[1] == 1:  # one record: Python's floats round as numpy's do, without two ufunc calls a sample
        _one_record(columns[:, 0], float(memory[0]), float(carried[0]))
        return outputs
    for row in columns:  # in place, two ufuncs a row
        np.add(row, carried, out=row)
        np.multiply(row, memory, out=carried)
    return outputs


def _one_record(record: np.ndarray, memory: float, carried: float) -> None:
    """``autoregressive`` in place on one record of gain·x_t, from φ·y_{−1} = ``carried``."""
    values = record.tolist()
    for t, value in enumerate(values):
        values[t] = value + carried
        carried = memory * values[t]
    record[:] = values


def _apply_ar(columns: np.ndarray, memories: np.ndarray) -> np.ndarray:
    """T·Q for the AR(1) correlation matrix T_ij = φ^|i−j| (a forward and a backward filter) at each φ of
    ``memories``: (rows, columns) → (rows, columns, memories)."""
    columns = columns[:, :, None]
    forward = autoregressive(columns, memories)
    backward = autoregressive(columns[::-1], memories)[::-1]
    return forward + backward - columns


def _lagged(a: np.ndarray, b: np.ndarray, lags: int) -> np.ndarray:
    """Σ_t a[t, …]·b[t + k, …] for k = 0 … lags (summed over the first axis, by FFT), shape (lags + 1, …)."""
    n = a.shape[0]
    size = scipy.fft.next_fast_len(2 * n)
    product = np.conj(np.fft.rfft(a, size, axis=0)) * np.fft.rfft(b, size, axis=0)
    return np.fft.irfft(product, size, axis=0)[: lags + 1]


def trend_basis(length: int, degree: int = 1) -> np.ndarray:
    """An orthonormal basis (length, degree + 1) of the polynomials of ``degree`` over a record's samples."""
    q, _ = np.linalg.qr(np.polynomial.legendre.legvander(np.linspace(-1.0, 1.0, length), degree))
    return q


def detrended_lag_sums(length: int, memory, lags: int, degree: int = 1) -> np.ndarray:
    """E[Σ_t e_t e_{t+k}], k = 0 … ``lags``, for unit-variance AR(1) noise of memory φ (0: white; one φ or
    an array of them, a row each) after a least-squares polynomial of ``degree`` (1: a line) is removed from a
    record of ``length`` samples: the diagonal sums of M·T·M, M = I − QQᵀ, in O(length · log length) per φ."""
    memories = np.atleast_1d(np.asarray(memory, dtype=np.float64))
    q = trend_basis(length, degree)
    k = np.arange(lags + 1)
    raw = (length - k)[None, :] * memories[:, None] ** k[None, :]  # 0⁰ = 1: white noise's n at lag 0
    tq = _apply_ar(q, memories)  # (length, degree + 1, memories)
    qcore = np.einsum("ti,ijm->tjm", q, np.einsum("ti,tjm->ijm", q, tq))  # Q·(Qᵀ·T·Q) for every φ
    qq = q[:, :, None]
    sums = raw - (_lagged(qq, tq, lags) + _lagged(tq, qq, lags) - _lagged(qcore, qq, lags)).sum(axis=1).T
    return sums if np.ndim(memory) else sums[0]


@functools.lru_cache(maxsize=256)
def _detrended_grid(length: int, lags: int, degree: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """``detrended_lag_sums`` of white noise, (lags + 1,), and at every memory of the grid, (memories,
    lags + 1): baselines of one length share them (a map's spots, a set's curves)."""
    sums = detrended_lag_sums(length, np.concatenate([[0.0], _MEMORIES]), lags, degree)
    return sums[0], sums[1:]


def fit_correlation(records: list[np.ndarray], lags: int, degree: int = 1) -> tuple[float, float, float]:
    """(c, φ, σ) of white + AR(1) noise fitted to the pooled sample autocorrelation of ``records`` (each with a
    polynomial of ``degree`` removed, 1: a line) at lags 1 … ``lags``, against its expectation for records of
    those lengths (so the detrending's bias is modelled, not ignored); σ is unbiased under the fitted model."""
    observed = sum(_lagged(r, r, lags) for r in records)
    grids = [_detrended_grid(r.size, lags, degree) for r in records]
    white = sum(g[0] for g in grids)
    ar = sum(g[1] for g in grids)  # (memories, lags + 1)
    shares = _SHARES[:, None, None]
    expected = (1.0 - shares) * white[None, None, :] + shares * ar[None, :, :]  # (shares, memories, lags + 1)
    misfit = np.sum((expected[..., 1:] / expected[..., :1] - observed[1:] / observed[0]) ** 2, axis=2)
    i, j = np.unravel_index(int(np.argmin(misfit)), misfit.shape)
    return float(_SHARES[i]), float(_MEMORIES[j]), math.sqrt(float(observed[0] / expected[i, j, 0]))


def _lags(records: list[np.ndarray], block: int) -> int:
    return int(max(2, min(block, min(r.size for r in records) // 3)))


def _from_records(records: list[np.ndarray], block: int, step: float, source: str, degree: int = 1) -> NoiseModel:
    share, memory, std = fit_correlation(records, _lags(records, block), degree)
    measured = [m for m in (block_inflation(r, block) for r in records) if m is not None]
    inflation = max(1.0, model_inflation(share, memory, block), float(np.median(measured)) if measured else 1.0)
    total = sum(r.size for r in records)
    return NoiseModel(
        std=std,
        lag1=share * memory,
        inflation=inflation,
        correlation_time=correlation_time(memory, step) if share > 0 else 0.0,
        source=source,
        samples=total,
        share=share,
        memory=memory,
        blocks=total / block,
        longest=max(r.size for r in records),
        record=records[0] if len(records) == 1 else None,
    )


def baseline_noise(time: np.ndarray, z: np.ndarray, force: np.ndarray, block: int) -> NoiseModel | None:
    """The noise model of a baseline (samples where the tip is free), or None if it is too short.

    A straight line force(z) is removed first: the baseline's offset and tilt are not noise; its slope is kept
    for the set's drift (``Drift``).
    """
    if force.size < MIN_BASELINE:
        return None
    start = settled(force, block)
    start += level_settled(z[start:], force[start:], block)
    noise, tilt = _line_removed(z[start:], force[start:])
    if not np.any(noise):
        return None
    step = float(np.median(np.diff(time)))
    spacing = float(np.median(np.diff(z[start:])))
    model = _from_records([noise], block, step, BASELINE)
    return replace(model, unsettled=start, slope=BaselineSlope(tilt, spacing, spacing / step, model.std))


def settled(force: np.ndarray, block: int = 50) -> int:
    """The first sample of a baseline that has settled: where the approach starts, the cantilever can ring
    (40–170 pN over the first 10–30% of the travel on public agarose curves whose noise is 12 pN after it),
    which is no noise of the contact. Each ``block`` of samples' variance about its own mean is compared
    with the largest of the second half's: where the first is ``RINGING`` times that or more, it and the
    leading blocks after it above that largest are left out. On a stationary record the blocks are
    exchangeable, so the first exceeds the largest of m others with probability 1/(m + 1) at all, and
    twice it far less often (white noise: never in 2000 records of 6 to 52 blocks; AR(1) of lag-1 0.9, 0.6%
    of 16-block records but 4% of 6-block ones); a burst later always
    stays in, and so does a start a little noisier than the rest (15 against 12.5 pN on a public PAAm
    record: as likely in contact)."""
    count = force.size // block
    if count < 4:
        return 0
    variances = force[: count * block].reshape(count, block).var(axis=1)
    ceiling = variances[count // 2 :].max()
    if variances[0] < RINGING * ceiling:
        return 0
    start = 0
    while start < count // 2 and variances[start] > ceiling:
        start += 1
    return start * block


def level_settled(z: np.ndarray, force: np.ndarray, block: int = 50) -> int:
    """The first sample of a baseline whose level has settled: where the piezo starts an approach, the force
    can sit off the baseline's line for its first blocks (public PAAm curves: 16–26 pN over the first 10–20 ms,
    under a noise of 13 pN whose 50-sample means scatter by 2 pN; left in, they read as memory and κ² came out
    4.2–8.3 against 1.4–2.0 without them, and real-noise.md's 0.8–2.0 for PAAm). The first block's mean
    departure from the record's line in z is compared with the largest of the second half's, as ``settled``
    compares variances: where it is ``LEVEL_SHIFT`` times that or more it is left out, and so is each next
    block that departs more than the largest from the line through it and the blocks after it (the shifted
    start tilts the first line). The rule reads the scatter of the record's own block means, so correlated
    noise raises its ceiling with it: stationary white + AR(1) noise (lag-1 0 to 0.997) lost its start in
    0.9–1.8% of 6-block records, at most 0.8% of 10-block, 0.2% of 20-block and none of 60-block ones (1000
    draws each)."""
    count = force.size // block
    start = 0
    while count - start >= 4 and start < count // 2:  # each leading block against a line through the rest
        rest = slice(start * block, count * block)
        departures = np.abs(_detrended(z[rest], force[rest]).reshape(count - start, block).mean(axis=1))
        if departures[0] <= (LEVEL_SHIFT if start == 0 else 1.0) * departures[(count - start) // 2 :].max():
            break
        start += 1
    return start * block


def rests_on_short_records(noise: NoiseModel) -> bool:
    """The set's correlation was read off baselines shorter than ``MIN_BASELINE``, or off none at all."""
    return SHORT_BASELINES in noise.source or noise.source == SECOND_DIFFERENCES


def residual_noise(
    records: list[np.ndarray], std: float, step: float, block: int, degree: int = 1, source: str = RESIDUAL
) -> NoiseModel | None:
    """The noise's correlation measured on a flexible model's residual where the baselines cannot give it
    (``rests_on_short_records``): each curve's residual in contact, a polynomial in time of ``degree`` removed
    (1: a line), fitted as the baselines are (white + AR(1), the detrending's bias modelled); σ stays ``std``
    (the baselines' or the lab's); ``source`` says which model's residual. A model that misses some structure
    leaves it in the records and raises κ²: the tests it feeds then err towards calling structure noise. None
    where no record holds ``MIN_BASELINE`` samples."""
    kept = [r for r in records if r.size >= MIN_BASELINE]
    if not kept:
        return None
    bases = [trend_basis(r.size, degree) for r in kept]
    detrended = [r - q @ (q.T @ r) for r, q in zip(kept, bases)]
    return replace(_from_records(detrended, block, step, source, degree), std=std, record=None)


def _detrended(z: np.ndarray, force: np.ndarray) -> np.ndarray:
    """The force with its least-squares line in z removed [N]."""
    return _line_removed(z, force)[0]


def _line_removed(z: np.ndarray, force: np.ndarray) -> tuple[np.ndarray, float]:
    """(the force with its least-squares line in z removed [N], that line's slope [N/m])."""
    design = np.column_stack([np.ones_like(z), z - z.mean()])
    coefficients, *_ = np.linalg.lstsq(design, force, rcond=None)
    return force - design @ coefficients, float(coefficients[1])


def robust_std(values: np.ndarray) -> float:
    """σ of Gaussian ``values`` from their median absolute deviation, 1.4826·MAD: a few outliers leave it be."""
    return 1.4826 * float(np.median(np.abs(values - np.median(values))))


def second_difference_std(force: np.ndarray) -> float:
    """σ of white force noise from second differences (robust MAD): 1.4826·MAD/√6."""
    return robust_std(np.diff(force, 2)) / np.sqrt(6.0)


def holds_noise(values: np.ndarray, scale: float) -> bool:
    """Whether ``values`` [N] scatter by more than rounding of a force of range ``scale`` [N] (``ROUNDING``)."""
    return float(np.std(values)) > ROUNDING * scale


def curve_noise(time, z, force, baseline: np.ndarray, block: int) -> NoiseModel:
    """The noise of one curve: measured on its ``baseline`` samples (bool mask) if long enough,
    else σ from second differences of the whole curve, correlation unknown (white until pooled; a
    baseline of ``MIN_RECORD`` samples or more is kept as a short record for the pool). A baseline flat to
    rounding gives σ 0 and no record (``SILENT``): there is no noise to measure; so does a curve whose second
    differences are mostly zero (``STUCK``: a detector stuck, or a force quantised coarser than its noise), whose
    robust σ is 0 (read as it was, a stuck curve's χ² divided by zero)."""
    short = _detrended(z[baseline], force[baseline]) if baseline.sum() >= MIN_RECORD else None
    if short is not None and not holds_noise(short, float(np.ptp(force))):
        return NoiseModel(0.0, 0.0, 1.0, 0.0, SILENT, int(force.size))
    measured = baseline_noise(time[baseline], z[baseline], force[baseline], block)
    if measured is not None:
        return measured
    std = second_difference_std(force)
    if not std > ROUNDING * float(np.ptp(force)):
        return NoiseModel(0.0, 0.0, 1.0, 0.0, STUCK, int(force.size))
    return NoiseModel(std, 0.0, 1.0, 0.0, SECOND_DIFFERENCES, int(force.size), short=short, differences=std)


def with_std(model: NoiseModel, std: float, where: str) -> NoiseModel:
    """``model`` with σ given elsewhere (``where``); the correlation stays what was measured."""
    return replace(model, std=std, source=f"std from {where}; correlation from the {model.source}", differences=None)


def corrected(curve: NoiseModel, correlation: NoiseModel) -> NoiseModel:
    """``curve`` with a σ read off second differences corrected for ``correlation``'s: Var(Δ²e) = σ²(6 − 8ρ₁ +
    2ρ₂), so correlated noise reads low there (AR(1) of ρ₁ 0.9: by 3.8×); other curves as they are. Not where
    the correlation rests on short baselines alone (``rests_on_short_records``): 3 × 36 samples of that noise
    gave corrected σ from 0.43 to 5.9 times the truth."""
    if curve.differences is None or rests_on_short_records(correlation):
        return curve
    return replace(curve, std=curve.differences * difference_factor(correlation))


def difference_factor(correlation: NoiseModel) -> float:
    """How many times low a σ read off second differences is under ``correlation``: √(6 / (6 − 8ρ₁ + 2ρ₂))."""
    rho1, rho2 = correlation.autocorrelation(np.array([1, 2]))
    return math.sqrt(6.0 / (6.0 - 8.0 * rho1 + 2.0 * rho2))


def pooled(
    models: list[NoiseModel], weights: list[float], steps: list[float], block: int = 50, false_alarm: float = 0.01
) -> NoiseModel:
    """The set's noise: σ averaged with ``weights`` (fitted samples per curve); the correlation fitted on
    every measured baseline at once (one instrument, one sample), short ones too where no curve has a long
    one, else white; the drift its long baselines' slopes hold beyond it at ``false_alarm`` (``drift``). A curve
    whose σ came from second differences has it corrected for that correlation (``corrected``)."""
    records = [m.record for m in models if m.record is not None]
    source = models[0].source
    if not records:
        records, source = [m.short for m in models if m.short is not None], SHORT_BASELINES
    if not records:
        std = float(np.average([m.std for m in models], weights=weights))
        return NoiseModel(std, 0.0, 1.0, 0.0, SECOND_DIFFERENCES, sum(m.samples for m in models))
    correlation = _from_records(records, block, float(np.median(steps)), source)
    stds = [corrected(m, correlation).std for m in models]
    sources = {m.source for m in models if m.record is not None}
    if not sources:  # short records only: say so, and where σ came from if not from them
        given = {m.source.split(";")[0] for m in models if m.source.startswith("std from")}
        sources = {f"{given.pop()}; correlation from the {SHORT_BASELINES}" if len(given) == 1 else SHORT_BASELINES}
    return replace(
        correlation,
        std=float(np.average(stds, weights=weights)),
        source=sources.pop() if len(sources) == 1 else BASELINE,
        record=None,
        unsettled=sum(m.unsettled for m in models),
        drift=drift(models, correlation, float(np.median(steps)), false_alarm),
    )


def set_drift(models: list[NoiseModel], steps: list[float], block: int = 50, false_alarm: float = 0.01) -> Drift | None:
    """``pooled``'s drift alone, under the correlation the curves' baselines share (``steps`` [s] their sampling
    steps): what a set's baseline levels are read against (its ``estimate``) before its noise is pooled
    (``ptwin.data.kinematics``). None where no baseline holds a record of its own."""
    records = [m.record for m in models if m.record is not None]
    if not records:
        return None
    step = float(np.median(steps))
    return drift(models, _from_records(records, block, step, BASELINE), step, false_alarm)


def drift(models: list[NoiseModel], correlation: NoiseModel, step: float, false_alarm: float) -> Drift | None:
    """What the curves' baseline slopes (``models``' own) say of the noise beyond the baselines' length, under the
    set's ``correlation`` (``Drift``; ``step`` [s] the sampling step); None where the slopes leave no degree of
    freedom. A free probe's slope in z is the instrument's tilt (virtual deflection), the same on every curve, plus
    the gradient of the fluid's drag as the gap closes, which grows with the speed: real PAAm approaches at 5 and
    15 µm/s rose by 1.70e-5 and 3.17e-5 N/m (standard errors 3e-7, 5e-7). So a line in the speed (a level where
    every curve has one speed) is fitted to the slopes, weights w_c the inverse of slope c's variance V_c under
    the model, and χ² is what it leaves. V_c is the baseline's own σ's (``BaselineSlope.scatter``): a σ given in
    meta.yaml describes the noise as a lab measured it, not the scatter these slopes were read against (three of
    four cell records scaled as the bench-sets scale them scatter at 0.76 of the σ given: slopes that drifted read
    as within it). Where each slope's variance is V_c(1 + s·r_c) (r_c: a unit drift's slope variance over the
    model's, the drift's variance s in units of the curve's σ²), χ²'s expectation is Σ (1 + s·r_c)(1 − h_c), h_c
    the fit's leverages: that gives s."""
    measured = [m for m in models if m.slope is not None and m.slope.step > 0 < m.slope.scatter and m.blocks >= 4]
    speeds = np.array([m.slope.speed for m in measured])
    design = np.ones((len(measured), 1))
    if speeds.size and np.ptp(speeds) > 0.01 * speeds.max():
        design = np.column_stack([design, speeds / speeds.max()])
    dof = len(measured) - design.shape[1]
    if dof < 1:
        return None
    lengths = [m.record.size for m in measured]
    memory = math.exp(-1.0 / float(np.median(lengths)))
    # never below white noise's, as κ² never is: a fitted anti-correlation would make noise alone read as drift
    white = [slope_variance(n, 0.0, 0.0) for n in lengths]
    model = np.maximum([slope_variance(n, correlation.share, correlation.memory) for n in lengths], white)
    # a unit drift of the curve's σ² over the model's slope variance at the baseline's own σ
    unit_drift = np.array(
        [slope_variance(n, 1.0, memory) * (m.std / m.slope.scatter) ** 2 for n, m in zip(lengths, measured)]
    )
    root = np.sqrt(np.array([(m.slope.step / m.slope.scatter) ** 2 for m in measured]) / model)  # √w_c, V_c in (N/m)²
    scaled = design * root[:, None]
    q, _ = np.linalg.qr(scaled)
    slopes = np.array([m.slope.value for m in measured]) * root
    chi_square = float(np.sum((slopes - q @ (q.T @ slopes)) ** 2))
    kept = 1.0 - np.sum(q**2, axis=1)
    share = (chi_square - kept.sum()) / float(np.sum(unit_drift / model * kept))
    beyond = chi_square > chi_square_exceeded(false_alarm, dof)
    estimate = max(float(share), 0.0)
    return Drift(chi_square, dof, estimate if beyond else 0.0, memory, correlation_time(memory, step), estimate)


def slope_variance(length: int, share: float, memory: float) -> float:
    """The variance of a least-squares line's slope per sample over ``length`` samples of unit-variance white +
    AR(1) noise (share c, memory φ): xᵀRx/(xᵀx)², x the samples about their middle (``correlated_square``)."""
    x = np.arange(length) - (length - 1) / 2.0
    return correlated_square(x, share, memory) / float(x @ x) ** 2


def correlated_square(values: np.ndarray, share: float, memory: float) -> float:
    """sᵀRs of a record s (``values``) under unit-variance white + AR(1) noise, R = (1 − c)I + cT_φ (T_ij =
    φ^|i−j|, share c, memory φ): sᵀs + 2c Σ_{i<k} s_i s_k φ^(k−i), the lagged sum by a recursive filter."""
    square = float(values @ values)
    if share == 0.0 or memory <= 0.0:
        return square
    return square + 2.0 * share * (float(values @ autoregressive(values, memory)) - square)
