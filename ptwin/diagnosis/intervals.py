"""95% intervals that hold under the noise model: profile likelihood.

For one parameter of a fitted model the profile χ²_p(θ) is the least χ² with θ fixed and every other parameter refitted
(a contact correction the fit holds too, within its range: ``held_range``). Under correlated noise the likelihood-ratio
statistic is Δχ²/κ² (κ²: the noise model's block-variance inflation; given the structure test's null, the noise model's
inflation along the parameter's own profile shape, or the inflation along it that the fit's own residual in contact
shows, where either is larger, read against F(1, ν): ``_noise_along``), also divided by the reduced χ² of the fit where
that exceeds 1 (the misfit is then larger than the noise model says, as the Wald variance assumes too), and the interval
is where it stays ≤ 3.84 (χ² with one degree of freedom). Each side is found on the raw parameter (log K, log M, log
tau: asymmetric intervals where the data are) by regula falsi (Illinois) on √Δ − √3.84, which is nearly linear in θ,
from the Wald step outward (each outward point where the line through the last two meets the level). A side the data do
not close within ``REACH`` steps of ×4 is None: the parameter is not bounded there. So is a side where the model stops
being evaluable before the data close it (e.g. K so small that the Darcy force overflows): a failure of the model is no
evidence against the parameter, and bisecting towards it would report the place where the arithmetic broke as a bound
the data set. Given points ``beyond`` (an interval found already), each side is searched only past its point: where the
profile closes before it, the point is returned (one refit a side where that is all a caller needs to know). Each
profile point's refit runs LM as the fits do (``physics_solver``): with LM's defaults it stopped short where K must move
far from the last point (a pore relaxation doing nothing at its fit on a soft cantilever: M's lower end 6.29e3 Pa for
3.78e3 converged)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import torch

from ptwin.data.noise import NoiseModel, correlated_square, mean_inflation, residual_noise
from ptwin.data.tails import fisher_exceeded
from ptwin.diagnosis.null import StructureTest
from ptwin.fitting.lm import FitError, Traced
from ptwin.fitting.physics_fit import (
    SETTLED,
    PhysicsFit,
    fitted_difference,
    held_range,
    physics_solver,
    scaled_residual,
)
from ptwin.physics.samples import Samples

LEVEL = 3.841458820694124  # the 95% point of χ² with one degree of freedom
REACH = 6  # outward steps (each ×4) before a side counts as open
ITERATIONS = 8  # regula falsi steps per side
RESTARTS = 2  # searches on past a bracket's outer point that a refit nearer to it reads inside (``_side``)
TOLERANCE = 0.01 * math.sqrt(LEVEL)  # |excess| that counts as on the side
PAST = 0.1 * TOLERANCE  # the excess an outward point aims at: just past the level, where it ends the side
READ_LAGS = 300  # lags of the fit's residual in contact whose correlation a profile reads too (``_noise_along``)
REFIT = 40  # LM iterations of the other parameters at each profile point (as the fits run LM: ``physics_solver``)


def profile_interval(
    fit: PhysicsFit,
    raw_name: str,
    raw_std: float,
    samples: Samples,
    index: torch.Tensor,
    beyond: tuple[float | None, float | None] = (None, None),
    starts: tuple[dict[str, float], ...] = (),
    test: StructureTest | None = None,
) -> tuple[float | None, float | None]:
    """The 95% interval of the raw parameter ``raw_name`` (a name among the model's free parameters, e.g.
    'fluid.log_permeability') on ``samples[index]``, in raw units, under ``test``, the structure test's null
    (``_noise_along``; None: κ²); ``raw_std`` its Wald std (the first step). None on a side the data do not close.
    ``beyond``: (low, high) raw points, each side searched past its point only (None, or a point on the other side
    of the fit: the whole side; ±inf: a side open already, not searched); a side closing before it is that point.
    ``starts``: raw values ({name: value}) each profile point is refitted from too, besides the last point's, the
    lowest χ² kept: where a term does nothing at the fit its gradient is nil there, and a warm refit never leaves
    that basin. Where ``fit`` holds the reference's contact correction, each profile point refits it too, within its
    range (``held_range``): held by choice, it is a nuisance like every other."""
    span = held_range(fit)
    extra = ("contact.reference",) if span is not None else ()
    vector, residual = scaled_residual(fit.model, samples, index, also=extra)
    theta = vector.get()
    j = vector.entry(raw_name)
    restarts = [{vector.entry(name): value for name, value in entries.items()} for entries in starts]
    contact = vector.entry("contact.reference") if extra else None
    others = [i for i in range(theta.numel()) if i != j]
    warm: dict = {}  # the others at the last profile point and its offset, each side starting from θ̂
    reduced = fit.chi_square / max(fit.samples - theta.numel() + len(extra), 1)
    scale = _noise_along(residual, theta, j, samples, index, test, fit) * max(1.0, reduced)

    def refitted(fixed: torch.Tensor, free: list[int]) -> torch.Tensor:
        """``fixed`` with its entries ``free`` refitted (from their values there)."""
        at = torch.tensor(free, dtype=torch.long, device=fixed.device)

        def partial(rest):
            return residual(fixed.index_put((at,), rest))

        rest = physics_solver(partial, fixed[at], vector, at).run(REFIT, settled=SETTLED) if free else fixed[at]
        return fixed.index_put((at,), rest)

    def settled(start: torch.Tensor) -> tuple[torch.Tensor, float]:
        """The others refitted from ``start``, and χ² there (``FitError`` where the model cannot be evaluated)."""
        full = refitted(start, others)
        if contact is not None and not span[0] <= full[contact].item() <= span[1]:  # held at an end, the rest refit
            full[contact] = min(max(full[contact].item(), span[0]), span[1])
            full = refitted(full, [i for i in others if i != contact])
        with torch.no_grad():
            return full, residual(full).square().sum().item()

    def excess(offset: float) -> float:
        """√(Δχ²/κ²) − √3.84 with the parameter at θ̂ + offset, the others refitted (warm, and from each restart).
        A point that would close the side, warm from a point farther out, is refitted from the fit's own others
        too: after a point far out (the first step, 1.96 Wald std of a parameter the curvature barely fixes) LM's
        refit did not find its way back within its steps. Real agarose with 4.9 Pa·s added, gamma fitted alone at
        4.9e-5: every point read as closing and the interval came back as the fit's value itself, 4.91e-05 to
        4.91e-05."""
        start = theta.clone()
        start[others] = warm["others"]
        start[j] = theta[j] + offset
        best = _lowest(settled, [start, *(_moved(start, entries) for entries in restarts)])
        closing = best is None or best[1] - fit.chi_square >= LEVEL * scale
        if closing and abs(warm["offset"]) > abs(offset):
            fresh = _moved(theta, {j: theta[j] + offset})
            best = min(filter(None, (best, _lowest(settled, [fresh]))), key=lambda pair: pair[1], default=None)
        if best is None:
            return math.inf
        full, chi_square = best
        warm["others"], warm["offset"] = full[others], offset
        delta = max(chi_square - fit.chi_square, 0.0) / scale
        return math.sqrt(delta) - math.sqrt(LEVEL)

    step = raw_std if math.isfinite(raw_std) and raw_std > 0 else max(abs(theta[j].item()), 1.0) * 0.1
    sides = []
    for sign, point in zip((-1.0, 1.0), beyond):
        warm["others"], warm["offset"] = theta[others].clone(), 0.0
        past = None if point is None or sign * (point - theta[j].item()) <= 0 else point - theta[j].item()
        end = _side(excess, sign * 1.96 * step, past)
        sides.append(None if end is None else theta[j].item() + end)
    return sides[0], sides[1]


def _noise_along(
    residual,
    theta: torch.Tensor,
    j: int,
    samples: Samples,
    index,
    test: StructureTest | None,
    fit: PhysicsFit | None = None,
) -> float:
    """What Δχ² is divided by along the profile of θⱼ before it is read against χ²₁: the largest of κ², λ and λ'
    along the shape a move of θⱼ leaves once the others are refitted (its Jacobian column less its least-squares
    projection on theirs), each times F(1, ν)'s 95% point over χ²₁'s, ν the independent samples its noise was
    read on (Student's t squared: the noise's own scale is estimated), as the term-shape test reads a gain
    (``null.term_evidence``). λ: the structure test's noise model, read off the baselines (``StructureTest
    .inflation_on``), ν its blocks. λ': the correlation of ``fit``'s own residual in contact
    (``_residual_correlation``), ν its samples over the inflation of their mean (``mean_inflation``). Without
    ``test`` (no noise model to judge by), κ² alone.

    κ² is the variance of block means over white noise's, and a smooth shape sums the noise over far more than
    a block: under the bench-sets' p07 noise (AR(1) of 20-sample memory, 40% white, κ² 15.6 at 50-sample blocks)
    K's shape on a null's base model read λ 10–580 where κ² was 4.9–45 (the memory read off 0.3 µm of baseline
    with it), and K's interval by κ² missed the truth at 7 of 30 seeds, by λ at 2, by λ and F(1, 9.2) at none.
    A baseline shows no correlation longer than itself: under the cells' drifting noise ×15 in the p06 setting
    (baselines of 330 samples, 1000 in contact) K's shape read λ 1.2–2.3 off the baselines and 15–69 off the
    named model's residual, and K's interval missed the truth at 7 of 18 relaxation sets (at none with λ'), its
    error 4.6% rms where its Wald std, by the baselines, was about 1%. Where the model cannot be linearised at its
    optimum, κ²."""
    modelled = samples.noise_inflation
    if test is None or test.tested is None:
        return modelled
    try:
        jacobian, _ = Traced(residual, theta).jacobian_and_value()
    except (ValueError, RuntimeError):
        return modelled
    column, rest = jacobian[:, j], torch.cat([jacobian[:, :j], jacobian[:, j + 1 :]], dim=1)
    if rest.shape[1]:
        column = column - rest @ torch.linalg.lstsq(rest, column[:, None]).solution[:, 0]
    if not torch.isfinite(column).all():
        return modelled
    shape = column.detach().cpu().numpy()
    modelled = max(modelled, test.inflation_on(index, shape, samples.noise_inflation)) * _student(test.noise_blocks)
    read = None if fit is None else _residual_correlation(fit, samples, index)
    if read is None:
        return modelled
    positions, curve = index.cpu().numpy(), samples.curve[index].cpu().numpy()
    independent = read.samples / mean_inflation(read.share, read.memory)
    return max(modelled, _correlated(shape, positions, curve, read) * _student(independent))


def _student(blocks: float) -> float:
    """F(1, ν)'s 95% point over χ²₁'s: a variance read off ν independent blocks."""
    return 1.0 if math.isinf(blocks) else fisher_exceeded(0.05, 1, blocks) / LEVEL


def _residual_correlation(fit: PhysicsFit, samples: Samples, index: torch.Tensor) -> NoiseModel | None:
    """The correlation (white + AR(1), ``residual_noise``) of ``fit``'s residual in contact in noise units, each
    curve's a record less its line, read at lags up to ``READ_LAGS``; None where no curve holds 100 samples in
    contact. A residual holds the noise and what the model misses, so this reads the noise's correlation or more;
    the structure test, which names what a model misses, never reads it."""
    with torch.no_grad():
        scaled = fitted_difference(fit.model, samples, index) / samples.noise_floor
    records = [record.cpu().numpy() for record in samples.in_contact_by_curve(scaled)]
    return residual_noise(records, 1.0, 1.0, READ_LAGS, 1, "the fit's residual in contact")


def _correlated(shape: np.ndarray, positions: np.ndarray, curve: np.ndarray, noise: NoiseModel) -> float:
    """λ' = sᵀRs / sᵀs of ``shape`` s on the samples at ``positions`` (sample numbers; R within each ``curve``:
    ρ(k) = c·φ^|k| of ``noise``'s share c and memory φ beside its white part), each curve's samples a record with
    zeros where ``positions`` skip one (``correlated_square``)."""
    norm = float(shape @ shape)
    if norm <= 0.0:
        return 1.0
    correlated = 0.0
    for c in np.unique(curve):
        on = curve == c
        full = np.zeros(positions[on].max() - positions[on].min() + 1)
        full[positions[on] - positions[on].min()] = shape[on]
        correlated += correlated_square(full, noise.share, noise.memory)
    return correlated / norm


def _lowest(settle, starts: list[torch.Tensor]) -> tuple[torch.Tensor, float] | None:
    """The lowest finite (θ, χ²) that ``settle`` refits from each of ``starts``; None where none is."""
    found = []
    for start in starts:
        try:
            found.append(settle(start))
        except FitError:
            continue
    found = [(full, chi_square) for full, chi_square in found if math.isfinite(chi_square)]
    return min(found, key=lambda pair: pair[1]) if found else None


def _moved(theta: torch.Tensor, entries: dict[int, float]) -> torch.Tensor:
    """θ with ``entries`` ({index: value}) set."""
    moved = theta.clone()
    for i, value in entries.items():
        moved[i] = value
    return moved


def within(interval: list[float | None], plausible: tuple[float, float]) -> list[float | None]:
    """``interval`` with each side outside the ``plausible`` range (low, high) open (None): a bound no sample
    could be near (K < 7e26 m², from a profile that never closed; K > 3e23 m², from a fit run off into a
    degenerate corner) says nothing."""
    return [None if side is None or not plausible[0] <= side <= plausible[1] else side for side in interval]


def _side(excess, first: float, past: float | None = None, restarts: int = RESTARTS) -> float | None:
    """The offset where ``excess`` crosses zero, from 0 (where it is −√3.84) outward through ``first``; given an
    offset ``past``, from there outward, or ``past`` itself where ``excess`` is no longer negative there. Outward,
    each point is where the line through the last two crosses the level (``_outward``), so a profile close to its
    quadratic is closed at its first or second point; the side is open where it has not closed by ``REACH``
    steps of ×4.

    A profile point is a refit, and a refit that jumps far from the last point can stop short of its minimum: the
    point outside then reads closed where, refitted warm from nearby, it is inside, and regula falsi crowds against
    it. Where the bracket has not closed within ``ITERATIONS``, its outer point is refitted again (warm from the
    bracket's inner end) and, read inside, the side is searched on from there (``restarts`` times at most). A
    soft cantilever's viscosity (γ 10 beside K 6e-16 m², real PAAm noise, two speeds): K's upper side stopped at
    5.78e-16 m², a point read +0.29 refitted from 2.8% nearer the fit and −0.48 from nearby; searched on, it
    closes at 5.83e-16."""
    inside, g_inside = 0.0, -math.sqrt(LEVEL)
    outside, farthest = first, first * 4.0 ** (REACH - 1)
    if past is not None:
        if math.isinf(past):
            return None
        g_past = excess(past)
        if math.isinf(g_past):
            return None
        if g_past >= 0:
            return past
        farthest = past * 4.0**REACH
        inside, g_inside, outside = past, g_past, _outward(inside, g_inside, past, g_past, farthest)
    for step in itertools.count():
        g_outside = excess(outside)
        if math.isinf(g_outside):  # the model broke down first: no evidence of a bound
            return None
        if 0 <= g_outside < TOLERANCE:  # just past the level: the end (just short of it is no end: a profile
            return outside  # flattening out below the level closes nowhere)
        if g_outside >= 0:
            break
        if abs(outside) >= abs(farthest):
            return None
        secant = step < ITERATIONS  # then ×4: a profile steepening ever faster never crawls out in small steps
        inside, g_inside, outside = outside, g_outside, _outward(inside, g_inside, outside, g_outside, farthest, secant)
    side = 0
    for _ in range(ITERATIONS):
        point = _on_line(inside, g_inside, outside, g_outside, 0.0)
        g = excess(point)
        if abs(g) < TOLERANCE:
            return point
        if math.isinf(g):
            return None
        if g < 0:
            inside, g_inside = point, g
            if side == -1:
                g_outside *= 0.5
            side = -1
        else:
            outside, g_outside = point, g
            if side == 1:
                g_inside *= 0.5
            side = 1
    if restarts and excess(outside) < 0:
        return _side(excess, first, outside, restarts - 1)
    return 0.5 * (inside + outside)


def _outward(
    inside: float, g_inside: float, outside: float, g_outside: float, farthest: float, secant: bool = True
) -> float:
    """The next offset past ``outside`` (both points still inside the interval): where the line through the two
    reaches ``PAST`` (a point within the tolerance past the level is the end), at least 1.001 and
    at most 4 times ``outside`` (4 times where not ``secant``), and never past ``farthest``."""
    ratio = 4.0
    if secant and g_outside > g_inside:
        ratio = min(max(_on_line(inside, g_inside, outside, g_outside, PAST) / outside, 1.001), 4.0)
    return outside * ratio if abs(outside * ratio) < abs(farthest) else farthest


def _on_line(inside: float, g_inside: float, outside: float, g_outside: float, level: float) -> float:
    """The offset where the line through (``inside``, ``g_inside``) and (``outside``, ``g_outside``) reaches ``level``
    of the excess: regula falsi's next point (``level`` 0), and an outward point's aim (``PAST``)."""
    return inside + (level - g_inside) * (outside - inside) / (g_outside - g_inside)
