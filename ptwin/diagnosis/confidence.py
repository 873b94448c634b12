"""How sure a named term is: evidence on held-out curves, and the grade.

Held-out curves: each fitted curve in turn is left out, the model with the named set
and the model without the term are refitted on the others (from the full fit, so a
few LM steps), and both predict the curve they never saw. The gain is the ratio of
their RMS over all held-out curves, each model's residual there less the lines that curve's baseline
allows (``fitted_difference``, as every fit reads a residual: raw, the lines' errors, the same for both
models, buried what they differ by); the term's parameters across the folds show
whether the curves agree on them, among the folds that still hold every kind of segment
(a fold without the only hold fits the approaches alone: a different question).

The grade (README, "Confidence"):
- strong: removing the term costs ≥ 3 × the BIC margin under the noise model, no other
  candidate explains the data as well, its values are plausible, and on held-out curves
  it gains ≥ the held-out margin with parameters that agree across folds (relative
  spread ≤ ``STABLE``, or within ``AGREE`` standard errors of each fold's own fit);
- moderate: at most one shortfall, and a mild one — a smaller BIC cost (still ≥ the
  margin), too few curves to hold one out, or parameters that vary across folds;
- weak: anything else, in particular a confounded, implausible or held-out-contradicted
  term, one whose gain on the validation samples is within what noise and model error give
  (named because it alone leaves no structure where the base model leaves it), one left
  untested where a fold could not be fitted (``FoldFailed``), one whose 95%
  profile interval under the noise model reaches the value where it does nothing (γ = 0,
  M → ∞): the tests that named it weigh its own shape, the interval every nuisance refitted
  with it; or one named beside structure that no term explains (its size is what it takes in
  a model that misses the data). The reasons are given in words either way.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import torch

from ptwin.diagnosis.words import short_of, times_better
from ptwin.fitting.lm import FitError
from ptwin.fitting.physics_fit import PhysicsFit, fit_physics, fitted_difference, held_as
from ptwin.physics.samples import Samples

STABLE = 0.5  # largest relative spread of a parameter across folds
AGREE = 3.0  # standard errors within which two folds' values agree whatever their relative spread
FOLD_ITERATIONS = 20


@dataclass
class HeldOut:
    """A named set against a smaller one, on curves each fitted without."""

    gain: float  # RMS of the smaller set / RMS of the named set, pooled over the held-out curves
    spread: dict[str, float]  # 'term.param' → (max − min)/|median| across folds
    folds: int


@dataclass
class FoldFailed:
    """Curves left out that could not be tested: a fit without one of them failed (``reason``, in words). Never
    read as "too few curves": a term that could not be tested on a curve it was not fitted to is not trusted."""

    reason: str


OnCurvesLeftOut = HeldOut | FoldFailed | None  # None: fewer than two fitted curves, none to leave out


def held_out_curves(
    make_model: Callable,
    samples: Samples,
    seen: torch.Tensor,
    named: PhysicsFit,
    smaller: PhysicsFit,
) -> OnCurvesLeftOut:
    """``named`` against ``smaller`` on curves left out one at a time (None with fewer than two fitted
    curves; ``FoldFailed`` when a fold cannot be fitted); fits start from the full fits' values, the reference's contact
    correction fitted or held as in the full fits (``ptwin.fitting.physics_fit.fit_with_starts``)."""
    if len(samples.curve_ids) < 2:
        return None
    errors = {"named": 0.0, "smaller": 0.0}
    kinds = set(samples.segment[seen].tolist())

    def comparable(rest):  # a fold without every kind of segment answers another question (a hold's relaxation)
        return set(samples.segment[rest].tolist()) == kinds

    values: dict[str, list[tuple[float, float]]] = {}  # 'term.param' → (value, std) of each fold
    for curve in range(len(samples.curve_ids)):
        held = seen[samples.curve[seen] == curve]
        rest = seen[samples.curve[seen] != curve]
        for key, fit in (("named", named), ("smaller", smaller)):
            model = held_as(make_model(fit.terms, fit.params, fit.permeability), fit)
            try:
                refit = fit_physics(model, samples, rest, FOLD_ITERATIONS, reference_free=fit.reference_free)
            except FitError as error:
                return FoldFailed(f"the fit without curve {samples.curve_ids[curve]!r} failed: {error}")
            with torch.no_grad():
                errors[key] += fitted_difference(refit.model, samples, held)[held].square().sum().item()
            if key == "named" and comparable(rest):
                for term, params in refit.params.items():
                    for name, value in params.items():
                        values.setdefault(f"{term}.{name}", []).append((value, refit.param_std[term][name]))
    spread = {name: _spread(v) for name, v in values.items()}
    gain = math.sqrt(errors["smaller"] / errors["named"]) if errors["named"] > 0 else math.inf
    return HeldOut(gain, spread, len(samples.curve_ids))


def _spread(folds: list[tuple[float, float]]) -> float:
    """(max − min)/|median| of a parameter across folds, or 0 when no two folds differ by more than
    ``AGREE`` standard errors of their difference (each fold's own, under the noise model): a spread the
    folds' noise explains is no disagreement. Under a common value a pair differs by more than 3 standard
    errors with probability 0.3% (fold estimates share most of their data, so this errs towards agreeing)."""
    ordered = sorted(folds)
    median = ordered[len(ordered) // 2][0]
    significant = any(
        abs(a - b) > AGREE * math.hypot(sa, sb) for i, (a, sa) in enumerate(ordered) for b, sb in ordered[i + 1 :]
    )
    if not significant:
        return 0.0
    return (ordered[-1][0] - ordered[0][0]) / abs(median) if median != 0 else math.inf


@dataclass
class Grade:
    confidence: str  # strong, moderate or weak
    reasons: list[str] = field(default_factory=list)  # the shortfalls, in words


def grade(
    removal_cost: float,
    confounded_with: list[str],
    implausible: str | None,
    held_out: OnCurvesLeftOut,
    bic_margin: float,
    heldout_margin: float,
    absent_within: Sequence[str] = (),
    unexplained: str | None = None,
    unproven: str | None = None,
) -> Grade:
    """The confidence of one named term from its evidence (rules in the module docstring); ``absent_within``:
    the values where the term does nothing that its 95% intervals reach, in words (e.g. 'gamma = 0');
    ``unexplained``: the structure the named model leaves, in words (None: none); ``unproven``: its gain on the
    validation samples, in words, where that is within what noise and model error give (None: beyond it)."""
    mild, serious = [], []
    if unproven is not None:
        serious.append(f"on the validation samples {unproven}")
    if unexplained is not None:
        serious.append(
            f"structure remains that no term of the vocabulary explains ({unexplained}), so its size is what it "
            "takes in a model that misses the data, with no interval"
        )
    if removal_cost < 3 * bic_margin:
        mild.append(f"removing it costs only {removal_cost:.0f} BIC under the noise model")
    if confounded_with:
        serious.append("the data explain as well with " + " or ".join(confounded_with))
    if implausible:
        serious.append(implausible)
    if absent_within:
        serious.append(
            f"its 95% interval under the noise model reaches {' and '.join(absent_within)}, where it does nothing"
        )
    if held_out is None:
        mild.append("too few curves to test it on a curve it was not fitted to")
    elif isinstance(held_out, FoldFailed):
        serious.append(f"it could not be tested on curves left out of the fit ({held_out.reason})")
    else:
        if held_out.gain < 1:
            serious.append(f"on curves left out of the fit it predicts {times_better(held_out.gain)}")
        elif held_out.gain < 1 + heldout_margin:
            serious.append(
                f"on curves left out of the fit it improves the prediction by only "
                f"{short_of(100 * (held_out.gain - 1), 100 * heldout_margin, 0)}% (needs {100 * heldout_margin:.0f}%)"
            )
        unstable = {name: s for name, s in held_out.spread.items() if not s <= STABLE}
        if unstable:
            mild.append(
                "its value changes between curves ("
                + ", ".join(f"{name} by {_percent(s)}" for name, s in unstable.items())
                + ")"
            )
    if not mild and not serious:
        return Grade("strong")
    if not serious and len(mild) == 1:
        return Grade("moderate", mild)
    return Grade("weak", serious + mild)


def _percent(spread: float) -> str:
    return f"{100 * spread:.0f}%" if math.isfinite(spread) else "more than its own size"
