"""Name the physics: fit base + every candidate subset jointly with K, then choose.

Selection, as measured to name the exact set on concealed effects: among the
*physical* fits take the lowest BIC, then prune any term whose removal costs less
than ``bic_margin`` BIC or less than ``heldout_margin`` of the validation RMS. BIC
alone admits spurious terms and held-out error alone cannot split some pairs, so a
term must pass both. Subsets of k terms are fitted only when the best of k − 1 leaves
structure (greedy forward selection would miss pairs whose members barely help alone;
fitting every pair whenever a single is not enough does not).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import torch

from ptwin.diagnosis.locate import pooled_whiteness
from ptwin.fitting.physics_fit import PhysicsFit, fit_with_starts, rmse
from ptwin.fitting.split import Split
from ptwin.physics.samples import Samples


@dataclass
class Candidate:
    fit: PhysicsFit
    val_rmse: float  # [N]
    whiteness: float  # of the residual on train + val

    @property
    def terms(self) -> tuple[str, ...]:
        return self.fit.terms


def fit_candidates(
    make_model: Callable,
    samples: Samples,
    split: Split,
    terms: list[str],
    max_terms: int,
    iterations: int,
    block: int,
    threshold: float,
    progress: Callable[[str], None] = print,
    fitted: dict[tuple[str, ...], PhysicsFit] | None = None,
) -> dict[tuple[str, ...], Candidate]:
    """Fits of the base model, every single term and, while the best subset of k − 1 terms leaves
    structure, every subset of k ≤ ``max_terms`` terms, on the train split.

    ``fitted``: fits already made on the same train split (e.g. the base model's), reused as they are.
    """
    fitted = fitted or {}
    seen = torch.cat([split.train, split.val]).sort().values
    candidates = {}

    def add(subset):
        fit = fitted.get(subset) or fit_with_starts(make_model, subset, samples, split.train, iterations)
        with torch.no_grad():
            residual = fit.model(samples)[seen] - samples.force[seen]
        structure = pooled_whiteness(samples, residual, seen, block)
        candidate = Candidate(fit, rmse(fit.model, samples, split.val), structure)
        candidates[subset] = candidate
        state = "physical" if fit.physical else "rejected: " + "; ".join(fit.violations.values())
        name = " + ".join(subset) or "base"
        progress(f"  {name:<55s} BIC {fit.bic:12.1f}  val RMS {candidate.val_rmse * 1e9:7.3f} nN  ({state})")

    add(())
    for size in range(1, max_terms + 1):
        previous = [c for t, c in candidates.items() if len(t) == size - 1 and c.fit.physical]
        best = min(previous, key=lambda c: c.fit.bic, default=None)
        if size > 1 and best is not None and best.whiteness <= threshold:
            break
        for subset in itertools.combinations(terms, size):
            add(subset)
    return candidates


def choose(candidates: dict, bic_margin: float, heldout_margin: float) -> tuple[tuple[str, ...], list[str]]:
    """The accepted subset and the reasons for every term pruned on the way."""
    physical = {t: c for t, c in candidates.items() if c.fit.physical}
    chosen = min(physical, key=lambda t: physical[t].fit.bic)
    notes = []
    pruned = True
    while pruned and chosen:
        pruned = False
        for term in chosen:
            without = tuple(t for t in chosen if t != term)
            if without not in physical:
                continue
            bic_cost = physical[without].fit.bic - physical[chosen].fit.bic
            heldout_cost = physical[without].val_rmse / physical[chosen].val_rmse - 1
            if bic_cost < bic_margin or heldout_cost < heldout_margin:
                notes.append(
                    f"{term} pruned: removing it costs {bic_cost:.1f} BIC and {100 * heldout_cost:.1f}% of the "
                    f"validation RMS (needs ≥ {bic_margin:g} and ≥ {100 * heldout_margin:g}%)"
                )
                chosen, pruned = without, True
                break
    return chosen, notes


def confounded(candidates: dict, chosen: tuple[str, ...], bic_margin: float, heldout_margin: float):
    """Other physical subsets of the chosen size that explain the data as well."""
    if not chosen:
        return []
    best = candidates[chosen]
    return [
        t
        for t, c in candidates.items()
        if len(t) == len(chosen)
        and t != chosen
        and c.fit.physical
        and abs(c.fit.bic - best.fit.bic) < bic_margin
        and abs(c.val_rmse / best.val_rmse - 1) < heldout_margin
    ]


def rejected(candidates: dict, bic_margin: float) -> list[dict]:
    """Single terms that would have lowered the BIC but only with a non-physical parameter."""
    base = candidates[()].fit.bic
    return [
        {"term": t[0], "params": c.fit.params[t[0]], "why": "; ".join(c.fit.violations.values())}
        for t, c in candidates.items()
        if len(t) == 1 and not c.fit.physical and base - c.fit.bic > bic_margin
    ]
