"""What noise alone reads: the structure test's null distribution under the noise model.

A residual (noise units) is structure when its whiteness W (``ptwin.diagnosis.locate``: block
means, so a misfit that persists over a block) exceeds what noise alone exceeds at the stated
false-alarm rate. Its mean square is no test: a soft cantilever's true model leaves 2–3 noise
variances in contact (the noise there is not the baseline's, real-noise.md), so it would
refuse right answers.

Under the base model with the right K, a fitted curve's residual is its own noise minus the
reference curve's noise, carried into every curve by the elastic law read off it (smoothed
onto depth nodes, interpolated). That second part is the same on every curve and smooth over
a block, so W sits well above 1 on null sets (g ≈ 1.7 on a stiff white-noise set, 50-sample
blocks; such sets read 2.6, the rest being model error, below). The residual is simulated
``REPLICATES`` times from the set's noise model (white +
AR(1), each curve's σ, the reference's σ through the law's own smoothing), W computed on each
exactly as on data, and the draws summarised as g·χ²(h)/h (Satterthwaite: g the mean, h =
2g²/variance). κ² itself was estimated on ν independent block means (``NoiseModel.blocks``),
so W read on data is that over χ²(ν)/ν:

    W ~ g · F(h, ν),

and a residual is structure when W exceeds its (1 − false alarm) quantile plus what a model
error of ``MODEL_ERROR`` of the noise std adds (B·e²/κ²): no model of real recordings is
exact, and a discrepancy of a tenth of the noise is physics nobody left out (the elastic law's
interpolation, the PGD basis, an independent instrument's elastic law). Not simulated:
the fit of K and the terms, nor that of the removed baselines' line errors, which a residual
is read less of (``ptwin.fitting.baseline_line``: they absorb a little of the noise, so the
test errs towards calling noise noise), and the isotonic step of the law (it only irons out
wiggles).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch

from ptwin.data.noise import NoiseModel, autoregressive
from ptwin.data.tails import chi_square_exceeded, fisher_exceeded
from ptwin.physics.elastic import ReferenceCurve
from ptwin.physics.samples import Samples

REPLICATES = 200
MODEL_ERROR = 0.15  # a systematic misfit this fraction of the noise std is tolerated as model error


@dataclass(frozen=True)
class ScaledF:
    """g · F(h, ν) (ν = inf: g · χ²(h)/h)."""

    scale: float  # g, the mean of W on noise alone
    dof: float  # h
    noise_blocks: float  # ν

    def quantile(self, false_alarm: float) -> float:
        if math.isinf(self.noise_blocks):
            return self.scale * chi_square_exceeded(false_alarm, self.dof) / self.dof
        return self.scale * fisher_exceeded(false_alarm, self.dof, self.noise_blocks)

    @classmethod
    def of(cls, draws: np.ndarray, noise_blocks: float) -> ScaledF:
        mean, variance = float(draws.mean()), float(draws.var())
        return cls(mean, 2.0 * mean**2 / variance if variance > 0 else math.inf, noise_blocks)


@dataclass(frozen=True)
class StructureTest:
    """W on noise alone, pooled over the curves and per curve (by index into ``samples.curve_ids``), and the
    simulated residuals themselves (noise units, on the tested samples), which say how much any one shape
    of misfit the noise alone can fake (``inflation_along``)."""

    whiteness: ScaledF
    curves: dict[int, ScaledF]
    false_alarm: float
    tolerated: float  # W a model error of MODEL_ERROR adds: block · e² / κ²
    draws: np.ndarray = field(compare=False, repr=False)  # (tested samples, REPLICATES)
    noise_blocks: float = math.inf  # ν: independent block means the noise model's correlation rests on
    tested: np.ndarray | None = field(default=None, compare=False, repr=False)  # the draws' samples (time-ordered)

    @property
    def threshold(self) -> float:
        """The pooled W above which a residual is structure."""
        return self.whiteness.quantile(self.false_alarm) + self.tolerated

    def curve_threshold(self, curve: int) -> float:
        return self.curves[curve].quantile(self.false_alarm) + self.tolerated

    def structured(self, whiteness: float) -> bool:
        return whiteness > self.threshold

    def inflation_along(self, shape: np.ndarray) -> float:
        """λ ≥ 1: the variance of the noise alone projected on ``shape`` (noise units, on the tested samples),
        over white noise's: correlation and the reference's noise carried by the elastic law make a smooth
        shape λ times easier to fake than white noise would."""
        norm = float(shape @ shape)
        if norm <= 0.0:
            return 1.0
        return max(1.0, float(np.mean((shape @ self.draws) ** 2)) / norm)

    def inflation_on(self, index: torch.Tensor, shape: np.ndarray, elsewhere: float) -> float:
        """λ of ``shape`` given on the samples ``index`` (noise units): its part on the tested samples as
        ``inflation_along`` reads it, the rest (samples the test does not simulate: those just before contact) at
        ``elsewhere`` (the set's κ²), each by its share of the shape's squared norm, the two parts' cross terms
        neglected."""
        samples = index.cpu().numpy()
        at = np.searchsorted(self.tested, samples).clip(max=self.tested.size - 1)
        on = self.tested[at] == samples
        tested = np.zeros(self.tested.size)
        tested[at[on]] = shape[on]
        inside, outside = float(shape[on] @ shape[on]), float(shape[~on] @ shape[~on])
        if inside + outside <= 0.0:
            return elsewhere
        return (self.inflation_along(tested) * inside + elsewhere * outside) / (inside + outside)

    def words(self, whiteness: float) -> str:
        """The statistic against its threshold, in words."""
        return (
            f"whiteness {whiteness:.1f} against {self.threshold:.1f}, what noise alone exceeds one time in "
            f"{1 / self.false_alarm:.0f}"
        )


def structure_test(
    samples: Samples,
    index: torch.Tensor,
    reference: ReferenceCurve | None,
    noise: NoiseModel,
    block: int,
    false_alarm: float,
    seed: int = 0,
) -> StructureTest:
    """The null distribution of W on the samples ``index`` (time-ordered) under ``noise``;
    ``reference``: the elastic law whose noise every residual shares (None: none, the curves' own noise)."""
    rng = np.random.default_rng(seed)
    inherited = 0.0
    if reference is not None:
        nodes = reference.smooth(_draw(rng, reference.samples, noise)) * reference.noise_std  # (nodes, R)
        nodes = torch.from_numpy(nodes).to(reference.depth_nodes.device)
        inherited = reference.interpolate(nodes, samples.depth[index].detach())  # (samples, R) [N]
        # The law's noise, read off the reference's force and depth, is gained in the residual as a sample's own is.
        inherited = (inherited * samples.noise_gain[index, None]).cpu().numpy()
    sigma = samples.noise_floor[index].detach().cpu().numpy()[:, None]
    residual = (sigma * _draw(rng, index.numel(), noise) - inherited) / sigma
    curve = samples.curve[index].detach().cpu().numpy()
    per_curve = {c: _whiteness(residual[curve == c], block) / samples.noise_inflation for c in np.unique(curve)}
    pooled = np.mean(list(per_curve.values()), axis=0)
    return StructureTest(
        ScaledF.of(pooled, noise.blocks),
        {int(c): ScaledF.of(w, noise.blocks) for c, w in per_curve.items()},
        false_alarm,
        block * MODEL_ERROR**2 / samples.noise_inflation,
        residual,
        noise.blocks,
        index.cpu().numpy(),
    )


def beyond_model_error(flexible: float, model: float, noise_std: float) -> bool:
    """A flexible model (validation RMS ``flexible`` [N]) predicts better than ``model`` by more than a model
    error of ``MODEL_ERROR`` of the noise std ``noise_std`` [N] would: (model² − flexible²)/σ² > MODEL_ERROR².
    The same tolerance as the structure test's: structure a flexible model captures only to that extent is
    no physics either model left out."""
    return (model**2 - flexible**2) / noise_std**2 > MODEL_ERROR**2


def _draw(rng: np.random.Generator, size: int, noise: NoiseModel) -> np.ndarray:
    """(size, REPLICATES) draws of white + AR(1) noise (share c, memory φ) of unit variance, stationary from
    the first sample (anti-correlated models are drawn white: κ² never goes below 1), plus the drift the set's
    baselines hold beyond the model (``NoiseModel.drift``; variance its share)."""
    white = rng.standard_normal((size, REPLICATES))
    share, memory = noise.share, noise.memory
    draws = white
    if share > 0.0 and memory > 0.0:
        draws = math.sqrt(1.0 - share) * white + math.sqrt(share) * _stationary_ar(rng, size, memory)
    if noise.drift is not None and noise.drift.share > 0.0:
        draws = draws + math.sqrt(noise.drift.share) * _stationary_ar(rng, size, noise.drift.memory)
    return draws


def _stationary_ar(rng: np.random.Generator, size: int, memory: float) -> np.ndarray:
    """(size, REPLICATES) draws of unit-variance AR(1) noise of memory φ, stationary from the first sample."""
    start = rng.standard_normal((1, REPLICATES))
    innovations = rng.standard_normal((size, REPLICATES))
    return autoregressive(innovations, memory, math.sqrt(1.0 - memory**2), start[0])


def _whiteness(scaled: np.ndarray, block: int) -> np.ndarray:
    """W of each column of a residual in noise units, blocks as ``locate.block_means`` makes them."""
    count = max(scaled.shape[0] // block, 1)
    edges = np.linspace(0, scaled.shape[0], count + 1).astype(int)
    sums = np.add.reduceat(scaled, edges[:-1], axis=0)
    lengths = np.diff(edges)[:, None]
    return np.mean(sums**2 / lengths, axis=0)


@dataclass(frozen=True)
class TermEvidence:
    """What one term gains over a smaller model, against what noise and model error could give it.

    The gain is Δχ² (noise units, on the fitted samples) over λ·s²: λ the inflation of the noise along the
    shape the term adds (``StructureTest.inflation_along``), s² the larger model's mean square residual (at
    least 1: in contact a soft cantilever's noise exceeds the baseline's). Under the smaller model with its
    noise, that is χ²(p) for the term's p parameters, F(p, ν)·p where the correlation rests on ν baseline
    blocks. A model error of ``MODEL_ERROR`` σ on each of the N samples, shaped like the term at worst, adds
    at most N·e²/(λ s²) in its root: the gain is beyond both when it exceeds

        (√(N e²/(λ s²)) + √q)²,   q the (1 − α) quantile of the noise part,

    which holds whatever the model error's shape (Cauchy–Schwarz), so the false-alarm rate is at most α.
    A term's specific shape is a far more powerful test than the whiteness of the whole residual, which
    has to guard against every shape at once."""

    term: str
    gain: float  # Δχ² / (λ s²)
    threshold: float
    inflation: float  # λ
    false_alarm: float  # α of this one test

    @property
    def beyond(self) -> bool:
        return self.gain > self.threshold

    def words(self) -> str:
        # A fit on the training samples can lose on the others: a negative gain is χ² the term adds there.
        gain = round(self.gain)
        units = f"{abs(gain)} unit{'' if abs(gain) == 1 else 's'} of χ²"
        change = f"takes {units} off" if gain >= 0 else f"adds {units} to"
        return (
            f"{self.term} {change} the residual under the noise model, where noise "
            f"and a model error of {MODEL_ERROR:g} noise std give at most {self.threshold:.0f} one time in "
            f"{1 / self.false_alarm:.0f}"
        )


def term_evidence(
    test: StructureTest,
    shape: np.ndarray,
    chi_square: tuple[float, float],
    samples: int,
    parameters: int,
    term: str,
    false_alarm: float,
) -> TermEvidence:
    """The ``TermEvidence`` of ``term``: ``shape`` is what it adds to the smaller model's forces on the
    tested samples of ``test`` (noise units), ``chi_square`` the smaller and the larger model's χ² on their
    ``samples`` fitted samples, ``parameters`` the term's, ``false_alarm`` this test's α."""
    smaller, larger = chi_square
    inflation = test.inflation_along(shape)
    scale = inflation * max(1.0, larger / samples)
    if math.isinf(test.noise_blocks):
        quantile = chi_square_exceeded(false_alarm, parameters)
    else:
        quantile = parameters * fisher_exceeded(false_alarm, parameters, test.noise_blocks)
    threshold = (math.sqrt(samples * MODEL_ERROR**2 / scale) + math.sqrt(quantile)) ** 2
    return TermEvidence(term, (smaller - larger) / scale, threshold, inflation, false_alarm)
