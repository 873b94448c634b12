"""Where a curve's contact point is unknown (``contact_point: estimate``, vendor imports):
its estimate, and the baseline offset and tilt removed from its force.

1. A first baseline: a straight line force(z) over the first fifth of the travel (from where
   it has settled, if the approach starts ringing: ``ptwin.data.noise.settled``), or, where
   the baseline is shorter than that, over the first 75% of the travel before the onset that a
   line beside a Hertz onset, fitted to the approach up to half its force, puts inside that
   fifth (``_line_onset``: on the demo's approach, 0.2 µm of baseline before 4 µm of travel in
   contact, a line through the first fifth followed the force into contact and put the contact
   405 nm late with a level of 24 nN, 80× the noise, removed); the contact guess is where the
   force leaves it for good (more than ``DEPARTURE`` robust standard deviations above it from
   there on).
2. The baseline: the line refitted over the first 75% of the travel before that guess
   (clear of the long-range forces just before contact); its offset and tilt (virtual
   deflection) are removed from the whole curve.
3. The refinement: with the baseline removed, the depth w = z − F/k_s, and the contact
   w0 where F = c·(w − w0)^1.5 fits the start of the indentation best, the samples before w0
   held at zero force (the Hertz shape of a sphere; a coarse grid then a fine one, c by
   linear least squares at each w0).
   A force that grows as √w from contact (a solid viscosity's π·γ·U·√(ρw)) is the
   first-order shape of a contact shift, so Hertz alone takes it for an earlier contact
   (26 ± 1 nm early on twelve simulated soft-cantilever curves with 5 Pa·s at 15 µm/s; with
   5 Pa·s added to real PAAm, 39 and 70 nm at 10 and 15 µm/s). So the onset is read again
   as Hertz beside a √w force (c, d ≥ 0), whose contact the samples before it place (1 ± 2 nm
   on those twelve), and how much later that contact is is kept (``Baseline.root_shift``):
   a fit of such a term starts its contact corrections there (``ptwin.pipeline.prepare``).
   It is no estimate of its own: without such a force it scatters ±5 nm about a point 6–7 nm
   late (Hertz alone: ±1 nm, unbiased), and any onset that is not Hertz's moves it.
4. The level removed: each curve's own, unless the levels of the set are one common level
   plus drag on the cantilever (o_i = a + b·v_i within their standard errors, themselves read off
   each baseline's noise and the drift the set's baseline slopes show, ``drifted``, ``levels_with_speed``):
   then only the common level is removed and the drag stays in the force, where
   ``cantilever_drag`` can be fitted; free per-curve levels would remove it unseen.

Why not nanite's estimators (``nanite.poc``): its Fréchet-distance guess lands well inside
contact when the baseline is short against the indentation (1.1 µm into a 4 µm Hertzian
indent after 1 µm of baseline, which spoilt the baseline line fitted before it), and its
fitted estimators take ~0.2 s a curve (too slow for force maps) with a shape-free
polynomial where a sphere's contact has a known shape. The fit refines each curve's
contact again, jointly with the physics (``ptwin.physics.contact``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ptwin.data.noise import correlated_square, fit_correlation, holds_noise, model_inflation, robust_std, settled
from ptwin.data.tails import chi_square_exceeded, fisher_exceeded, student_t_exceeded

DEPARTURE = 5.0  # robust standard deviations above the first baseline where contact has begun
SCAN = 101  # candidate contact depths per grid of the refinement
REJECT = 0.01  # how often levels that are one level plus drag are taken for free per-curve offsets
MIN_DOF = 2  # degrees of freedom the levels must leave a line to tell drag from offsets


@dataclass(frozen=True)
class Baseline:
    """One curve's estimated contact and the baseline removed from its force."""

    contact_z: float  # the file's z at the contact [m]: z − contact_z is the travel past contact
    offset: float  # the force removed at the contact [N]: the curve's own level, or the set's common level
    tilt: float  # its slope dF/dz [N/m] (virtual deflection)
    level: float = math.nan  # the curve's own baseline level at the contact [N]
    level_std: float = math.nan  # its standard error under the baseline's noise [N]
    level_dof: float = math.inf  # ν: the effectively independent baseline samples that error rests on
    onset: float = math.nan  # travel from the contact to where the force leaves the first baseline for good [m]
    common: bool = False  # the set's common level was removed (the levels are one level plus drag)
    root_shift: float = 0.0  # how much later the contact is where the onset is Hertz beside a √w force [m]
    # (n, Σt, Σt²) of the travel t from the contact [m] of the samples the line was fitted to: its (level, tilt)
    # known to precision [[n, Σt], [Σt, Σt²]]/σ² (white noise), what ``ptwin.fitting.baseline_line`` carries
    line_sums: tuple[float, float, float] | None = None
    level_drift: float = 0.0  # the part of ``level_std`` the set's drift adds [N] (``drifted``), in quadrature

    def with_offset(self, offset: float) -> Baseline:
        """This baseline with the set's common level ``offset`` [N] removed at the contact instead."""
        return replace(self, offset=offset, common=True)

    def remove(self, z: np.ndarray, force: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(z from the contact, force without the baseline) [m, N]."""
        travel = z - self.contact_z
        return travel, force - (self.offset + self.tilt * travel)


class NoBaseline(ValueError):
    """The approach starts in contact: no free travel to take a baseline from."""


def estimate_baseline(z: np.ndarray, force: np.ndarray, spring_constant: float) -> Baseline:
    """The contact and baseline of an approach (``z`` increasing into the sample [m], ``force`` [N])."""
    # Where the approach starts ringing, the baseline is read from where it has settled (``noise.settled``).
    start = settled(force[: z.size // 2])
    settled_from = np.arange(z.size) >= start
    end, where = z[start] + 0.2 * (z[-1] - z[0]), "in the first fifth of the travel"
    onset = _line_onset(z[start:], force[start:], spring_constant)
    if onset < end:  # a short baseline: the first fifth reaches into contact, and a line through it follows the force
        end, where = z[start] + 0.75 * (onset - z[start]), f"before the force's onset at z = {onset:.3g} m"
    first = settled_from & (z <= end)
    if first.sum() < 10:
        raise NoBaseline(f"fewer than 10 samples {where}")
    tilt, intercept = np.polyfit(z[first], force[first], 1)
    excess = force - (intercept + tilt * z)
    spread = robust_std(excess[first])
    below = np.flatnonzero(excess <= DEPARTURE * spread)
    guess = int(below[-1]) + 1 if below.size else 0
    free = settled_from & (z <= z[start] + 0.75 * (z[min(guess, z.size - 1)] - z[start]))
    if free.sum() < 10:
        raise NoBaseline("the force leaves the baseline within the first 10 samples")
    tilt, intercept = np.polyfit(z[free], force[free], 1)
    excess = force - (intercept + tilt * z)
    depth = z - excess / spring_constant
    contact_z, root_shift = _onset_contacts(depth, excess, depth[min(guess, z.size - 1)])  # F = 0 there: z = w
    level = float(intercept + tilt * contact_z)
    onset = abs(float(z[min(guess, z.size - 1)]) - contact_z)
    level_std, dof = _level_std(z[free], excess[free], contact_z, float(np.ptp(force)))
    travel = z[free] - contact_z
    sums = (float(travel.size), float(travel.sum()), float(np.square(travel).sum()))
    return Baseline(
        float(contact_z), level, float(tilt), level, level_std, dof, onset, root_shift=root_shift, line_sums=sums
    )


def drifted(baseline: Baseline, variance: float, memory: float) -> Baseline:
    """``baseline`` with its level's standard error widened by a drift of ``variance`` [N²] and lag-1 correlation
    ``memory`` per sample (the set's, ``ptwin.data.noise.Drift``): a noise that wanders over spans as long as the
    baseline moves its line's value at the contact as a whole, which the baseline's own noise model, read on it
    with its line removed, does not see. The level is the line's value at the contact, Σ aᵢ·Fᵢ over the baseline's
    samples (evenly spaced in travel, ``line_sums``), so the drift adds ``variance``·aᵀT_φa (T_ij = φ^|i−j|).
    The public cell records' noise on four simulated curves with drag (``tests/test_contact.py``): levels 0.145,
    0.524, 1.48 and 6.38 nN for drag of 0.1, 0.4, 1.6 and 6.4 nN, ± 0.023 nN (the fastest ± 0.18) as the baselines
    read them, rejected one level plus drag (χ² 25.8 on 2 degrees of freedom, beyond 20.1) and the drag went with
    each curve's level; the slopes of the same baselines read a drift of 0.30 σ², which makes each ± 0.10 nN (±
    0.21): χ² 2.5, b 9.75e-5 ± 3.5e-6 N s/m for 1e-4. As it is where there is no drift, no line or no noise (a
    level known to rounding)."""
    if variance <= 0.0 or baseline.line_sums is None or not baseline.level_std > 0.0:
        return baseline
    count, total, squares = baseline.line_sums
    n = int(round(count))
    centre, spread = total / count, squares - total**2 / count
    if n < 3 or spread <= 0.0:
        return baseline
    offsets = np.arange(n) - 0.5 * (n - 1)  # the samples about their middle, one spacing apart
    spacing = math.sqrt(spread / float(offsets @ offsets))
    weights = 1.0 / n - centre * spacing * offsets / spread  # the line's value at travel 0 (the contact)
    added = math.sqrt(variance * correlated_square(weights, 1.0, memory))
    return replace(baseline, level_std=math.hypot(baseline.level_std, added), level_drift=added)


def _level_std(z: np.ndarray, noise: np.ndarray, contact_z: float, scale: float) -> tuple[float, float]:
    """(standard error [N] of a line's value at ``contact_z`` fitted to ``noise`` at ``z``, under the noise's own
    correlation (white + AR(1), fitted on it): the white formula σ²(1/n + (z_c − z̄)²/Sxx) times the inflation of
    a mean over the whole stretch; the degrees of freedom ν it rests on, n over that inflation: the effectively
    independent samples). 0 where ``noise`` is rounding of a force of range ``scale`` [N] (``holds_noise``)."""
    n, centre = noise.size, z.mean()
    if not holds_noise(noise, scale):
        return 0.0, math.inf
    leverage = 1.0 / n + (contact_z - centre) ** 2 / np.sum((z - centre) ** 2)
    share, memory, std = fit_correlation([noise], max(2, min(50, n // 3)))
    inflation = max(1.0, model_inflation(share, memory, n))
    return std * math.sqrt(leverage * inflation), n / inflation


@dataclass(frozen=True)
class LevelsWithSpeed:
    """The curves' baseline levels o_i against one common level plus drag, o_i = a + b·v_i, weighted by
    their standard errors: under that model χ² follows χ²(curves − 2) where the errors are known, and
    χ²/dof F(curves − 2, ν) where each is read off its baseline's noise, ν effectively independent samples of it
    (``error_dof``, the least over the curves)."""

    common: float  # a [N]
    drag: float  # b [N s/m]
    drag_std: float
    chi_square: float
    dof: int
    error_dof: float = math.inf

    @property
    def consistent(self) -> bool:
        """The levels are one level plus drag: χ² within the model's (1 − ``REJECT``) quantile. Read on χ², AR(1)
        noise of 20-sample memory, 40% white, no offset (the bench-sets' p08 setting, four baselines of 1.2 µm,
        ν 7.9 at the median), rejected 8 of 200 null sets, 4% for the stated 1%: each error is read off one short
        baseline, and a level over it has Student's tails, not the normal's; on F, 3 of 200. Random per-curve
        offsets, no drag, are rejected as often as before under white noise (0.4 nN: 189 of 200, ν 250) and nearly
        so under AR(1) (discover-bench's "estimated" setting, 1 nN: 184 of 200, 194 on χ², ν 36), and taken for
        drag by ``shows_drag`` 2 and 3 times in 200."""
        return self.chi_square <= self.bound

    @property
    def bound(self) -> float:
        """The χ² levels that are one level plus drag exceed one time in 1/``REJECT`` (``consistent``)."""
        if math.isinf(self.error_dof):
            return chi_square_exceeded(REJECT, self.dof)
        return self.dof * fisher_exceeded(REJECT, self.dof, self.error_dof)

    @property
    def rise(self) -> float:
        """b over its standard error, that scaled by the levels' scatter about the line where it exceeds their
        standard errors (√(χ²/dof)): under levels that do not rise with speed, Student's t on ``dof``."""
        return self.drag / (self.drag_std * max(1.0, self.chi_square / self.dof) ** 0.5)

    @property
    def shows_drag(self) -> bool:
        """The levels are one level plus drag, and they rise with speed beyond what free per-curve offsets of
        their scatter would, one time in 1/``REJECT``: only then is the drag kept in the force. Levels that
        merely do not contradict a line (five random offsets that happen to order with speed) are offsets."""
        return self.consistent and self.rise > student_t_exceeded(REJECT, self.dof)


def levels_with_speed(
    levels: np.ndarray, stds: np.ndarray, speeds: np.ndarray, error_dof: float = math.inf
) -> LevelsWithSpeed | None:
    """The weighted fit of o_i = a + b·v_i (``stds`` each read off ``error_dof`` ν of noise at least; inf: known), or
    None when it cannot be told from free per-curve levels: fewer than three speeds (two levels are always one
    level plus drag), or fewer than ``MIN_DOF`` degrees of freedom (three levels of independent offsets a few
    times their standard errors apart fall within χ²(1)'s 99% quantile of some line about one time in ten, and
    would pass for drag)."""
    if np.unique(speeds).size < 3 or levels.size - 2 < MIN_DOF or not np.all(stds > 0):
        return None
    design = np.column_stack([np.ones_like(speeds), speeds]) / stds[:, None]
    target = levels / stds
    coefficients, *_ = np.linalg.lstsq(design, target, rcond=None)
    chi_square = float(np.sum((target - design @ coefficients) ** 2))
    covariance = np.linalg.inv(design.T @ design)
    common, drag, drag_std = float(coefficients[0]), float(coefficients[1]), float(np.sqrt(covariance[1, 1]))
    return LevelsWithSpeed(common, drag, drag_std, chi_square, len(levels) - 2, error_dof)


def baseline_levels(baselines: list[Baseline], speeds: list[float]) -> LevelsWithSpeed | None:
    """``levels_with_speed`` of the curves' ``baselines`` at their base ``speeds`` [m/s]."""
    levels, stds = np.array([b.level for b in baselines]), np.array([b.level_std for b in baselines])
    return levels_with_speed(levels, stds, np.array(speeds), min(b.level_dof for b in baselines))


def _onset_contacts(depth: np.ndarray, force: np.ndarray, guess: float) -> tuple[float, float]:
    """The onset's w0 read as Hertz alone, and how much later it is read as Hertz beside a √w force (the module
    docstring, step 3), over the approach up to half its largest force."""
    w, f = _to_half_force(depth, force)
    hertz = _scan(w, lambda candidates: _onset_misfit(w, f, candidates, with_root=False), guess)
    return hertz, _scan(w, lambda candidates: _onset_misfit(w, f, candidates, with_root=True), hertz) - hertz


def _line_onset(z: np.ndarray, force: np.ndarray, spring_constant: float) -> float:
    """The z [m] of the contact where a line (the baseline's level and tilt) beside a Hertz onset c·(w − w0)^1.5
    fits the approach best, up to half its largest force (w = z − F/k_s, F from the first samples' level): the
    onset found with no stretch of the travel taken for baseline first; inf where no onset of that shape fits."""
    level = force - np.median(force[:10])
    depth, f = _to_half_force(z - level / spring_constant, level)
    # The line is the same for every candidate: fitted beside the onset, it is the onset fitted to what the line
    # leaves of force and shape alike (Frisch–Waugh), one shape a candidate instead of three.
    line = np.linalg.qr(np.column_stack([np.ones_like(depth), z[: depth.size] - z[0]]))[0]
    f = f - line @ (line.T @ f)

    def misfit(candidates: np.ndarray) -> np.ndarray:
        hertz = np.clip(depth[None, :] - candidates[:, None], 0.0, None) ** 1.5
        return _misfit(f, hertz - (hertz @ line) @ line.T)

    onset = _scan(depth, misfit, 0.5 * float(depth[0] + depth[-1]))  # the coarse grid spans the depths
    if not np.isfinite(misfit(np.array([onset]))[0]):  # no onset of this shape (a snap to contact outweighs it)
        return math.inf
    return float(z[min(int(np.searchsorted(np.maximum.accumulate(depth), onset)), depth.size - 1)])


def _to_half_force(depth: np.ndarray, force: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``depth`` and ``force`` up to where the force first reaches half its largest (at least 20 samples)."""
    stop = max(int(np.argmax(force >= 0.5 * force.max())), 20)
    return depth[:stop], force[:stop]


def _scan(w: np.ndarray, misfit: Callable[[np.ndarray], np.ndarray], guess: float) -> float:
    """The w0 of least ``misfit`` (candidates → misfits) on a coarse grid about ``guess`` spanning ``w``'s range,
    then on a fine one around the best."""
    spacing = max(w[-1] - w[0], 1e-12) / (SCAN - 1)  # of the coarse grid
    best = guess
    for half_width in (0.5 * (SCAN - 1) * spacing, 4 * spacing):
        candidates = np.linspace(best - half_width, best + half_width, SCAN)
        best = float(candidates[int(np.argmin(misfit(candidates)))])
    return best


def _onset_misfit(w: np.ndarray, f: np.ndarray, candidates: np.ndarray, with_root: bool) -> np.ndarray:
    """The least misfit at each candidate w0 of F = c·t^1.5 (+ d·√t) (t = (w − w0)₊; c, d ≥ 0 by least squares):
    with the √t force, the least of Hertz alone, √t alone and the two together (the optimum over c, d ≥ 0 is
    one of them)."""
    travel = np.clip(w[None, :] - candidates[:, None], 0.0, None)
    hertz = travel**1.5
    if not with_root:
        return _misfit(f, hertz)
    root = np.sqrt(travel)
    return np.minimum.reduce([_misfit(f, hertz), _misfit(f, root), _misfit(f, hertz, root)])


def _misfit(f: np.ndarray, *shapes: np.ndarray) -> np.ndarray:
    """Σ (f − Σ_k c_k·shape_k)² for each row of the shapes (one a candidate contact), the c_k by least squares;
    inf where a c_k is not positive (no force grows from a contact by pulling) or the shapes do not determine
    them (a contact past every sample)."""
    design = np.stack(shapes, axis=-1)  # (candidates, samples, shapes)
    norm = np.sqrt(np.einsum("csk,csk->ck", design, design))
    usable = np.all(norm > 0, axis=1)
    design = design / np.where(norm > 0, norm, 1.0)[:, None, :]  # unit columns: the normal equations stay scaled
    gram = np.einsum("csk,csl->ckl", design, design)
    usable &= np.linalg.det(gram) > 1e-12
    gram[~usable] = np.eye(len(shapes))
    coefficients = np.linalg.solve(gram, np.einsum("csk,s->ck", design, f)[..., None])[..., 0]
    residual = f[None, :] - np.einsum("csk,ck->cs", design, coefficients)
    misfit = np.einsum("cs,cs->c", residual, residual)
    misfit[~usable | np.any(coefficients <= 0, axis=1)] = np.inf
    return misfit
