"""Name the physics: fit base + every candidate subset jointly with K, then choose.

Selection: among the *physical* fits take the lowest BIC, then prune, the least costly first,
any term whose removal costs less than ``bic_margin`` BIC, or less validation χ² than noise
and a model error of ``MODEL_ERROR`` noise std would give it one time in ``1/false_alarm``
(``HeldOutTest``). BIC alone admits spurious terms (a model error of a tenth of the noise
earns any margin over thousands of samples) and held-out error alone cannot split some
pairs, so a term must pass both. Every subset of k terms is fitted when the best of k − 1
leaves structure (greedy forward selection would miss pairs whose members barely help alone;
fitting every pair whenever a single is not enough does not). Where it leaves none but the base
model did, the best of k − 1 is still grown by one term each (the forward step), if it beats
every smaller subset by the BIC margin: under correlated noise the whole-residual test passes a
large term's fit with a smaller term beside it unmodelled (a pore relaxation, M 5e4, beside a
viscosity, γ 12, in the bench-sets' p07 setting: the pair 71 BIC below the viscosity alone, every
value right, the pore alone doing nothing). So it is where the base model's residual passes for noise
but a subset is beyond it in its own shape (``shape_evidence``): that subset is named alone, and a term
beside it that the selection cannot prove still moves K, which K's interval must reach
(``diagnose._not_ruled_out``; a solid relaxation, g 0.1 and tau 0.1 s, beside a viscosity, γ 10, on a
soft cantilever: the viscosity named weak with K 28% low, its interval [1.36e-16, 1.63e-16] m² beside
the truth 2e-16 until the pairs grown from it were fitted: [1.32e-16, 4.49e-16]). Where the base model's residual
passes for noise and no subset is beyond it in its own shape (``shape_evidence``), the subsets
of k − 1 that beat every smaller one by the BIC margin at values the field has are grown by one
term each: the information criterion sees something in them that the whole-residual test, on
few baseline blocks, cannot prove, and a single term short of its own shape evidence may be
half of a pair that has it. Either way, where a subset so grown beats every smaller one by the BIC
margin, k terms are needed and the k − 1 it was grown from may only stand in for one of them, so
every subset of k terms is fitted: in the realism suite's "pair viscosity + strain perm., AR(1)"
at seed 3 a drag alone (BIC 238.2) stood in for the viscosity, the drag with a strain-dependent K
(153.1) was named strong for both, and the pair concealed, never fitted, ends at 67.2 with each
value right; at seed 4, the residual within the noise, drag with a strain-dependent K was the pair
listed beside the base model, its K 19% off, and the interval missed the truth. The fits are made
to nest (``_nest``): no subset ends above one it contains, nor above one that contains it with the
extra term taken out, so that what a term gains is its own.
"""

from __future__ import annotations

import collections
import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ptwin.diagnosis.locate import pooled_whiteness
from ptwin.diagnosis.null import StructureTest, TermEvidence, term_evidence
from ptwin.fitting.lm import FitError
from ptwin.fitting.physics_fit import PhysicsFit, fit_from, fit_with_starts, fitted_difference, kept_first
from ptwin.fitting.split import Split
from ptwin.physics.samples import Samples


@dataclass
class Candidate:
    """One subset of terms, fitted with K on the train split (or the reason it could not be)."""

    terms: tuple[str, ...]
    fit: PhysicsFit | None  # None: the fit failed
    val_rmse: float  # [N]
    whiteness: float  # of the residual on train + val, in units of the noise model
    failure: str | None = None  # why the fit failed
    residual: np.ndarray | None = None  # model − measured on the judged samples (noise units); None: failed
    pinning: np.ndarray | None = None  # model − measured on the samples just before contact (noise units)

    @property
    def usable(self) -> bool:
        """A fit that can explain: it converged to physical values at which every term still acts."""
        return self.fit is not None and self.fit.usable

    @property
    def without_effect(self) -> bool:
        """A failed fit, or a physical one with a term that does nothing (ran off to a limit, or below the noise)."""
        return self.fit is None or (self.fit.physical and bool(self.fit.degenerate))

    def leaves_structure(self, test: StructureTest) -> bool:
        return test.structured(self.whiteness)

    @property
    def state(self) -> str:
        """'physical', or why this candidate cannot be an explanation."""
        if self.fit is None:
            return f"fit failed: {self.failure}"
        if not self.fit.physical:
            return "rejected: " + self.fit.why_not_physical
        if self.fit.degenerate:
            return "; ".join(f"{term} does nothing ({why})" for term, why in self.fit.degenerate.items())
        return "physical"


def fit_candidates(
    make_model: Callable,
    samples: Samples,
    split: Split,
    terms: list[str],
    max_terms: int,
    iterations: int,
    block: int,
    test: StructureTest,
    progress: Callable[[str], None] = print,
    fitted: dict[tuple[str, ...], PhysicsFit] | None = None,
    bic_margin: float = math.inf,
    reused: dict[tuple[str, ...], Candidate] | None = None,
    exhaustive: bool = False,
) -> dict[tuple[str, ...], Candidate]:
    """Fits of the base model, every single term and, while the best usable subset of k − 1 terms (none
    usable: the best smaller one) leaves structure, every subset of k ≤ ``max_terms`` terms, on the train
    split. Where it leaves none, the subsets of k that contain one of k − 1 beating every smaller one by
    ``bic_margin`` (the module docstring): the best such one where the base model leaves structure or a subset
    is beyond the noise in its own shape (the forward step), every such one where neither holds.
    Where a subset so grown beats every smaller one by ``bic_margin``, every other subset of its size is fitted
    too (the module docstring).
    A fit that fails is kept with its reason (``Candidate.failure``) and left out of every choice.

    ``fitted``: fits already made on the same train split (e.g. the base model's), reused as they are;
    ``reused``: candidates already made of them on these samples (``diagnose.first_fits``'), taken whole and
    not listed again; ``exhaustive``: every subset of up to ``max_terms`` terms, whatever the smaller ones leave.
    Every other candidate makes a line of ``progress``.
    """
    fitted, reused = fitted or {}, reused or {}
    judged = split.judged(samples), split.pinning(samples)
    candidates = {}

    def add(subset, fit=None, how=""):
        if fit is None and subset in reused:
            candidates[subset] = reused[subset]
            return
        base = candidates[()].fit if () in candidates else None
        fit = fit or fitted.get(subset)
        candidate = _candidate(subset, fit, make_model, samples, split, judged, iterations, block, base)
        candidates[subset] = candidate
        name = " + ".join(subset) or "base"
        figures = f"BIC {candidate.fit.bic:12.1f}  val RMS {candidate.val_rmse * 1e9:7.3f} nN" if candidate.fit else ""
        progress(f"  {name:<55s} {figures:<37s}  ({candidate.state}){how}")

    def refit(subset, start: tuple[str, ...], grown: bool = False, steps: int | None = None) -> PhysicsFit | None:
        """``subset`` fitted from ``start``'s optimum (``fit_from``) in up to ``steps`` LM steps (None: the fits'
        own cap; 0: left at that optimum, where it has that fit's cost and stopping state)."""
        try:
            fit = candidates[start].fit
            cap = iterations if steps is None else steps
            found = fit_from(make_model, subset, fit, samples, split.train, cap, follow, grown=grown)
        except FitError:
            return None  # ``add`` fits it from every start instead
        return found if steps != 0 else replace(found, settled=fit.settled)

    add(())
    follow = None if candidates[()].fit is None else candidates[()].fit.reference_free
    base_within_noise = not candidates[()].leaves_structure(test)
    for size in range(1, max_terms + 1):
        subsets, forward = _to_fit(candidates, terms, size, test, bic_margin, None if exhaustive else base_within_noise)
        if not subsets:
            break
        for subset in subsets:
            fit = None if forward is None else refit(subset, forward.terms, grown=True)
            add(subset, fit, f" grown from {' + '.join(forward.terms)}" if fit else "")
        _nest(candidates, refit, add, bic_margin)
        if preferred_subsets(candidates, size, bic_margin):  # k terms needed: the k − 1 may stand in for one
            for subset in itertools.combinations(terms, size):
                if subset not in candidates:
                    add(subset)
            _nest(candidates, refit, add, bic_margin)
        base_within_noise = not candidates[()].leaves_structure(test)
    return candidates


def _to_fit(
    candidates: dict, terms: list[str], size: int, test: StructureTest, bic_margin: float, within: bool | None
) -> tuple[list[tuple[str, ...]], Candidate | None]:
    """The subsets of ``size`` terms ``fit_candidates`` fits next, and the candidate the forward step grows them from
    (None: each fitted from its own starts); ``within``: whether the base model's residual is within the noise
    (None: every subset, whatever the smaller ones leave)."""
    # The best usable subset one term smaller (none usable: the best smaller one, the base model at least).
    previous = [c for t, c in candidates.items() if len(t) == size - 1 and c.usable]
    previous = previous or [c for t, c in candidates.items() if len(t) < size and c.usable]
    best = min(previous, key=lambda c: c.fit.bic, default=None)
    subsets = list(itertools.combinations(terms, size))
    if size == 1 or best is None or best.leaves_structure(test) or within is None:
        return subsets, None
    preferred, forward = preferred_subsets(candidates, size - 1, bic_margin), None
    if not within or (preferred and any(e.beyond for e in shape_evidence(candidates, test).values())):
        forward = best if best.terms in preferred else None
        preferred = [best.terms] if forward else []
    return [subset for subset in subsets if any(set(p) <= set(subset) for p in preferred)], forward


NESTED_SLACK = 0.1  # χ² (noise units) by which two fits may break nesting before one is refitted from the other


def _nest(candidates: dict, refit: Callable, add: Callable, bic_margin: float = math.inf) -> None:
    """Make the fits nest: each subset's χ² no more than that of every subset of it one term smaller, and no more
    than the cost of every subset one term larger with that term taken out (``PhysicsFit.chi_square_without``), by
    ``NESTED_SLACK``. Every fit is a local optimum reached from a few starts, and one subset's starts can find a
    basin its neighbour's missed. On real PAAm (two speeds) a relaxation alone ended at BIC 223, relaxation with
    a viscosity of 0.07 ± 0.7 Pa·s at 113, and the viscosity was named (weak) for what the relaxation alone had
    missed: refitted from the pair's optimum, the relaxation alone reaches 107. On another, a power law with a
    strain-dependent permeability of m 7e-7 ended at 316, above the power law alone (252) and the base model (301).
    What a term gains over a smaller model must be the term's, so a fit breaking the nesting is fitted again from
    its neighbour's optimum (``fit_from``: no worse than it) and kept where better (``kept_first``, as
    ``fit_with_starts`` keeps its best). Where the fits nest this costs nothing; larger subsets are repaired from
    first, so that a repaired one can repair those below it.

    A physical fit that stays above a smaller one after that (LM from the smaller optimum left the physical region)
    stands for its model while it is within ``bic_margin`` of the smaller one: another basin the data do not rule
    out says so, and what it says of K counts (a solid relaxation with no fluid force at all on a soft null of two
    speeds, 9.2 BIC above the base model: K not fixed). Beyond the margin it is no rival of anything and says only
    that LM found a poor basin; it is replaced by the smaller optimum with the term where it does nothing, the least
    χ² known of a physical fit of its model, where the term is read as doing nothing. A weak power law on a soft
    cantilever (seed 7 of the rheology suite, α 0.03 concealed) ended at α 0.078, 64 BIC above the base model, so
    no rival of it; refitted from the base model it reached α < 0 below the base model's χ² (as on the shared p03:
    α 0.048 at χ² 544.1, α −0.018 at 528.8, the base model 530.7). Held there it is one: the data cannot tell the
    two apart."""

    def repaired(subset: tuple[str, ...], start: tuple[str, ...], how: str, steps: int | None = None) -> bool:
        """``subset`` refitted from ``start``'s optimum (``refit``), kept where better; whether it was."""
        fit, old = refit(subset, start, steps=steps), candidates[subset].fit
        if fit is None or (old is not None and kept_first(fit) >= kept_first(old)):
            return False
        add(subset, fit, how)
        return True

    def nested_pairs():
        for larger in sorted(candidates, key=len, reverse=True):
            for term in larger:
                smaller = tuple(t for t in larger if t != term)
                if smaller in candidates:
                    yield smaller, larger, term

    for _ in range(len(max(candidates, key=len)) + 1):  # a repair can open one more a level down
        changed = False
        for smaller, larger, term in list(nested_pairs()):
            small, large = candidates[smaller].fit, candidates[larger].fit
            if (
                large is not None
                and large.physical
                and (small is None or large.chi_square_without[term] < small.chi_square - NESTED_SLACK)
            ):
                changed |= repaired(smaller, larger, f" refitted from {' + '.join(larger)} with {term} taken out")
        for smaller, larger, term in reversed(list(nested_pairs())):
            small, large = candidates[smaller].fit, candidates[larger].fit
            if (
                small is not None
                and small.physical
                and (large is None or large.chi_square > small.chi_square + NESTED_SLACK)
            ):
                start = " + ".join(smaller) or "base"
                if repaired(larger, smaller, f" refitted from {start} with {term} added"):
                    changed = True
                elif large is not None and large.physical and large.bic > small.bic + bic_margin:
                    changed |= repaired(larger, smaller, f" held at {start}'s optimum, {term} doing nothing", steps=0)
        if not changed:
            return


def shape_evidence(candidates: dict, test: StructureTest) -> dict[str, TermEvidence]:
    """``TermEvidence`` of each usable subset over the base model, by its label (``' + '.join(terms)``); each
    test at the structure test's false-alarm rate over the number of subsets of its size tried, so that the
    single terms read noise as a term at most that often, and the pairs (weighed only where no single is beyond
    the noise in its own shape: ``diagnose._select``) at most that often."""
    base = candidates[()]
    tried = collections.Counter(len(t) for t in candidates if t)
    return {
        " + ".join(terms): term_evidence(
            test,
            c.residual - base.residual,  # what the subset adds on the judged samples (noise units)
            (base.fit.chi_square, c.fit.chi_square),
            c.fit.samples,
            # the terms' own parameters: a nuisance each fit may free or hold is no part of them
            sum(len(c.fit.params[term]) for term in terms),
            " + ".join(terms),
            test.false_alarm / tried[len(terms)],
        )
        for terms, c in candidates.items()
        if terms and c.usable
    }


def preferred_subsets(candidates: dict, size: int, bic_margin: float) -> list[tuple[str, ...]]:
    """The usable subsets of ``size`` terms, at values the field has (``PhysicsFit.plausible``), that beat every
    usable smaller subset by ``bic_margin``."""
    smaller = min((c.fit.bic for t, c in candidates.items() if len(t) < size and c.usable), default=math.inf)
    return [
        t
        for t, c in candidates.items()
        if len(t) == size and c.usable and c.fit.plausible and c.fit.bic <= smaller - bic_margin
    ]


def _candidate(subset, fit, make_model, samples, split, judged, iterations, block, base=None) -> Candidate:
    """``judged``: (the judged samples, those just before contact), as ``Split`` gives them."""
    try:
        fit = fit or fit_with_starts(make_model, subset, samples, split.train, iterations, base)
    except FitError as error:
        return Candidate(subset, None, math.inf, math.inf, str(error))
    seen, pins = judged
    difference = fitted_difference(fit.model, samples, split.train)  # one evaluation for every residual below
    scaled, pinning = ((difference[i] / samples.noise_floor[i]).cpu().numpy() for i in (seen, pins))
    whiteness = pooled_whiteness(samples, difference[seen], seen, block)
    val_rmse = difference[split.val].square().mean().sqrt().item()  # ``physics_fit.rmse`` on split.val
    return Candidate(subset, fit, val_rmse, whiteness, residual=scaled, pinning=pinning)


@dataclass(frozen=True)
class HeldOutEvidence:
    """What one model gains over another on the validation samples: in contact, and on the samples just before
    contact too, each part a ``TermEvidence`` at its share of the false-alarm rate."""

    parts: tuple[TermEvidence, ...]

    @property
    def beyond(self) -> bool:
        return any(part.beyond for part in self.parts)

    @property
    def gain(self) -> float:
        """The units of χ² the larger model takes off the validation samples, in contact and before it together."""
        return sum(part.gain for part in self.parts)

    def words(self) -> str:
        contact, *pinning = (part.words() for part in self.parts)
        return contact + "".join(f"; on the samples just before contact, {words}" for words in pinning)


@dataclass(frozen=True)
class HeldOutTest:
    """Whether one model predicts the validation samples better than another beyond what noise and model error
    give: ``null.term_evidence`` on the validation share of the judged samples (``validation``, a mask over
    them). Under the other model with its noise, the drop in validation χ² is at most the square of the
    residual's projection on the direction the better model adds (2 r·s − s² ≤ (r·ŝ)²); that direction was
    fitted on the train samples, so noise along it is ``test``'s (correlation, the reference's noise shared)
    and a model error of ``MODEL_ERROR`` σ adds at most its Cauchy–Schwarz bound: a false-alarm rate of at
    most ``false_alarm`` a decision, as the shape evidence has on the train samples.

    Where contacts are estimated, the validation samples that pin them (``pinning``: the null of the noise model
    on those samples, no elastic law there; ``pinning_validation``, a mask over them) are a second test: a force
    shaped like √w from contact (a solid viscosity) is a contact shift to first order, so in contact the contact
    nuisances absorb it and only the samples before contact, which stay at the baseline, show where the contact
    is. Each test at half the false-alarm rate, a term kept where either is beyond: at most ``false_alarm`` a
    decision (Bonferroni). A real force before contact that no model has (long-range, a curved baseline) counts
    in the larger model's mean square residual there (``term_evidence``'s s²), which scales the gain down."""

    test: StructureTest
    validation: np.ndarray  # bool over the judged samples
    false_alarm: float
    pinning: StructureTest | None = None  # the noise model's null on the samples just before contact
    pinning_validation: np.ndarray | None = None  # bool over those samples

    def evidence(self, smaller: Candidate, larger: Candidate, label: str) -> HeldOutEvidence:
        """What ``larger`` gains over ``smaller`` on the validation samples, ``label`` naming what it adds."""
        # the parameters of the terms ``larger`` adds (a nuisance a fit may free or hold is no part of them)
        parameters = max(sum(len(larger.fit.params[t]) for t in larger.terms if t not in smaller.terms), 1)
        parts = [(self.test, self.validation, smaller.residual, larger.residual)]
        if self.pinning is not None and smaller.pinning is not None and larger.pinning is not None:
            parts.append((self.pinning, self.pinning_validation, smaller.pinning, larger.pinning))
        false_alarm = self.false_alarm / len(parts)
        return HeldOutEvidence(tuple(_gain(*part, parameters, label, false_alarm) for part in parts))


def _gain(test, validation, smaller, larger, parameters: int, label: str, false_alarm: float) -> TermEvidence:
    """``term_evidence`` of the residual ``larger`` (noise units, on ``test``'s samples) against ``smaller`` on the
    ``validation`` share of them."""
    gained = np.where(validation, smaller - larger, 0.0)
    chi_square = float(np.sum(smaller[validation] ** 2)), float(np.sum(larger[validation] ** 2))
    # no validation sample there (a set of a few samples): no gain, so nothing is kept on the BIC alone
    samples = max(int(validation.sum()), 1)
    return term_evidence(test, gained, chi_square, samples, parameters, label, false_alarm)


def choose(candidates: dict, bic_margin: float, held_out: HeldOutTest) -> tuple[tuple[str, ...], list[str]]:
    """The accepted subset and the reasons for every term pruned on the way. Each term is weighed against
    ``weighed_against``'s subset: where the chosen set without it is not usable, a term that only keeps another
    physical (or acting) is pruned with that other unless the two together pay. Of the terms that fail, the one
    whose removal costs the least BIC goes first (backward elimination): pruned in the vocabulary's order, a
    viscosity that cost 16.7 BIC to remove and fell short on the validation samples went before the relaxation
    beside it, which cost 5.5, and the relaxation then fell alone (real PAAm with 5 Pa·s added)."""
    usable = {t: c for t, c in candidates.items() if c.usable}
    chosen = min(usable, key=lambda t: usable[t].fit.bic)
    notes = []
    while chosen:
        failing = []
        for term in chosen:
            without = weighed_against(usable, chosen, term)
            if without not in usable:  # not even the base model is usable: nothing to weigh it against
                continue
            bic_cost = usable[without].fit.bic - usable[chosen].fit.bic
            gain = held_out.evidence(usable[without], usable[chosen], term)
            if bic_cost < bic_margin or not gain.beyond:
                failing.append((bic_cost, term, without, gain))
        if not failing:
            break
        bic_cost, term, without, gain = min(failing, key=lambda f: f[0])
        # from which subset: the notes also say what each term does alone
        source = f" from {' + '.join(chosen)}" if len(chosen) > 1 else ""
        notes.append(
            f"{term} pruned{source}{together_with(chosen, without, term)}: removing it costs {bic_cost:.1f} "
            f"BIC (needs ≥ {bic_margin:g}), and on the validation samples {gain.words()}"
        )
        chosen = without
    return chosen, notes


def weighed_against(candidates: dict, chosen: tuple[str, ...], term: str) -> tuple[str, ...]:
    """The subset a named ``term`` is weighed against: ``chosen`` without it where that model is usable, else its
    usable subset of least BIC (the base model at least). A model that is not physical, or in which a term does
    nothing, explains nothing, so a term that only keeps another usable is weighed with that other against the
    model without both: real agarose with 5 Pa·s added named pore_pressure_relaxation + power_law_rheology, where
    pore_pressure_relaxation alone implies an elastic law that falls with depth and power_law_rheology costs 22 BIC
    beside it; weighed against that model, its evidence read "the BIC falls by -22" and it was never prunable."""
    without = tuple(t for t in chosen if t != term)
    subsets = [t for t, c in candidates.items() if c.usable and set(t) <= set(without)]
    if without in subsets:
        return without
    return min(subsets, key=lambda t: candidates[t].fit.bic, default=())


def together_with(chosen: tuple[str, ...], without: tuple[str, ...], term: str) -> str:
    """Words for the other terms ``without`` (``weighed_against``'s) drops beside ``term``, the chosen set without
    ``term`` being no explanation (not physical, or a term in it does nothing); '' where it drops none."""
    others = [t for t in chosen if t != term and t not in without]
    return f" together with {' + '.join(others)} (no explanation without {term})" if others else ""


def confounded(candidates: dict, chosen: tuple[str, ...], bic_margin: float, held_out: HeldOutTest):
    """Other usable subsets of the chosen size that explain the data as well by either measure: a term is
    kept only if removing it costs the BIC margin and the held-out test (``choose``), so a rival is told
    apart only if it falls short of the chosen subset by both."""
    if not chosen:
        return []
    best = candidates[chosen]
    return [
        t
        for t, c in candidates.items()
        if len(t) == len(chosen)
        and t != chosen
        and c.usable
        and (c.fit.bic - best.fit.bic < bic_margin or not held_out.evidence(c, best, " + ".join(chosen)).beyond)
    ]


def without_structure(candidates: dict, test: StructureTest, plausible: bool = False) -> list[Candidate]:
    """The usable subsets of fewest terms whose fits leave no structure ``test`` sees, the least BIC first; with
    ``plausible``, only those at values the field has (``PhysicsFit.plausible``), the fewest terms among them."""
    shaped = [
        c
        for terms, c in candidates.items()
        if terms and c.usable and not c.leaves_structure(test) and (c.fit.plausible or not plausible)
    ]
    if not shaped:
        return []
    smallest = min(len(c.terms) for c in shaped)
    return sorted((c for c in shaped if len(c.terms) == smallest), key=lambda c: c.fit.bic)


def rejected(candidates: dict, bic_margin: float) -> list[dict]:
    """Single terms that would have lowered the BIC but only with a non-physical parameter, and
    single terms whose fit failed (``why``: 'fit failed: …')."""
    base = candidates[()].fit.bic
    listed = []
    for terms, c in candidates.items():
        if len(terms) != 1:
            continue
        if c.fit is None:
            listed.append({"term": terms[0], "params": {}, "why": c.state})
        elif not c.fit.physical and base - c.fit.bic > bic_margin:
            listed.append({"term": terms[0], "params": c.fit.params[terms[0]], "why": c.fit.why_not_physical})
    return listed
