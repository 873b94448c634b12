"""The diagnosis stage: locate, name, refit, and say it in the contract's terms
(``diagnosis.json``, shared/physics-terms.md: ``Diagnosis.to_json`` is its one writer)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import torch

from ptwin.diagnosis.locate import Mismatch, locate
from ptwin.diagnosis.name import Candidate, choose, confounded, fit_candidates, rejected
from ptwin.fitting.hybrid import HybridTwin
from ptwin.fitting.hybrid_training import rmse_of
from ptwin.fitting.physics_fit import PhysicsFit, rmse
from ptwin.fitting.pointwise import ApparentPermeability
from ptwin.fitting.split import Split
from ptwin.physics.samples import Samples
from ptwin.physics.terms import VOCABULARY

FORMAT = "ptwin-diagnosis/1"
POORLY_IDENTIFIED = 0.5  # relative standard deviation
CORRELATED = 0.95  # |correlation| with K


@dataclass
class DiagnosisSettings:
    """What the diagnosis tries and how it decides (the ``diagnosis`` config group).

    ``terms``: the candidates (default: the whole vocabulary; [] fits the base model only);
    ``max_terms``: the largest subset fitted together.
    """

    terms: list[str] = field(default_factory=lambda: list(VOCABULARY))
    max_terms: int = 2
    bic_margin: float = 10.0  # a term stays only if removing it costs at least this much BIC ...
    heldout_margin: float = 0.10  # ... and at least this fraction of the validation RMS
    block: int = 50  # samples per block of the whiteness test
    whiteness_threshold: float = 5.0  # block statistic above which a residual is structure, not noise

    def __post_init__(self):
        unknown = [t for t in self.terms if t not in VOCABULARY]
        if unknown:
            raise ValueError(f"diagnosis.terms: unknown {unknown}; the vocabulary is {', '.join(VOCABULARY)}")
        if self.max_terms < 0:
            raise ValueError(f"diagnosis.max_terms must be ≥ 0, got {self.max_terms}")


@dataclass
class Diagnosis:
    detected: bool
    summary: str
    where: list[Mismatch]
    chosen: tuple[str, ...]
    candidates: dict[tuple[str, ...], Candidate]
    left_out: list[dict]
    rejected: list[dict]
    confounded: list[dict]
    unexplained: bool
    whiteness: dict[str, float]  # base / corrected
    fit: dict[str, dict[str, float]]  # base / corrected / hybrid → val_rmse, test_rmse [N]
    noise_floor: float
    notes: list[str] = field(default_factory=list)

    @property
    def base(self) -> Candidate:
        return self.candidates[()]

    @property
    def corrected(self) -> Candidate:
        return self.candidates[self.chosen]

    def to_json(self) -> dict:
        """``diagnosis.json`` as shared/physics-terms.md specifies."""
        return {
            "format": FORMAT,
            "mismatch": {
                "detected": self.detected,
                "summary": self.summary,
                "where": [
                    {
                        "curve": m.curve,
                        "depth_from": m.depth_from,
                        "depth_to": m.depth_to,
                        "rms_residual": m.rms_residual,
                        "noise_floor": m.noise_floor,
                    }
                    for m in self.where
                ],
            },
            "left_out": self.left_out,
            "rejected": self.rejected,
            "confounded": self.confounded,
            "unexplained": self.unexplained,
            "permeability": {
                "base": self.base.fit.permeability,
                "corrected": self.corrected.fit.permeability,
                "corrected_std": self.corrected.fit.permeability_std,
            },
            "noise_floor": self.noise_floor,
            "fit": self.fit,
        }


def diagnose(
    make_model: Callable,
    samples: Samples,
    split: Split,
    hybrid: HybridTwin,
    apparent: ApparentPermeability,
    settings: DiagnosisSettings,
    iterations: int,
    noise_floor: float,
    progress: Callable[[str], None] = print,
    base_fit: PhysicsFit | None = None,
) -> Diagnosis:
    """Run the diagnosis on the fitted samples of ``samples`` (``split`` over them); candidate fits run
    ``iterations`` LM steps; ``noise_floor`` [N] is the run's; ``base_fit``: the base model already
    fitted so on ``split.train``, if any."""
    s = settings
    seen = torch.cat([split.train, split.val]).sort().values
    progress("diagnosis: fitting the base model and the candidate terms (K refitted with each)")
    candidates = fit_candidates(
        make_model,
        samples,
        split,
        s.terms,
        s.max_terms,
        iterations,
        s.block,
        s.whiteness_threshold,
        progress,
        {(): base_fit} if base_fit is not None else None,
    )
    base = candidates[()]
    with torch.no_grad():
        base_residual = base.fit.model(samples)[seen] - samples.force[seen]
    detected = base.whiteness > s.whiteness_threshold
    where = locate(samples, base_residual, seen, s.block, s.whiteness_threshold) if detected else []
    chosen, notes = choose(candidates, s.bic_margin, s.heldout_margin) if detected else ((), [])
    corrected = candidates[chosen]
    unexplained = detected and (not chosen or corrected.whiteness > s.whiteness_threshold)
    if unexplained and chosen:
        notes.append(
            f"{' + '.join(chosen)} lowers the BIC most but leaves structure (whiteness {corrected.whiteness:.1f} > "
            f"{s.whiteness_threshold:g}): not claimed"
        )
        chosen, corrected = (), base
    fit = _fit_table(samples, split, base, corrected, hybrid)
    with torch.no_grad():
        learned = hybrid.network(samples)[seen]
        named = corrected.fit.model(samples)[seen] - base.fit.model(samples)[seen]
    confounds = [
        {
            "terms": [" + ".join(chosen), " + ".join(other)],
            "tell_apart": "; ".join(VOCABULARY[t].TELL_APART for t in sorted(set(chosen) ^ set(other))),
        }
        for other in confounded(candidates, chosen, s.bic_margin, s.heldout_margin)
    ]
    context = _Context(samples, split, candidates, corrected, fit, noise_floor, _explained_fraction(learned, named))
    left_out = sorted(
        (_left_out_entry(term, chosen, context, confounds) for term in chosen), key=lambda e: -e["test_rmse_gain"]
    )
    diagnosis = Diagnosis(
        detected=detected,
        summary="",
        where=where,
        chosen=chosen,
        candidates=candidates,
        left_out=left_out,
        rejected=rejected(candidates, s.bic_margin) if detected else [],
        confounded=confounds,
        unexplained=unexplained,
        whiteness={"base": base.whiteness, "corrected": corrected.whiteness},
        fit=fit,
        noise_floor=noise_floor,
        notes=notes,
    )
    diagnosis.summary = summarise(diagnosis, apparent, s.whiteness_threshold)
    return diagnosis


@dataclass
class _Context:
    """What every left-out entry is measured against."""

    samples: Samples
    split: Split
    candidates: dict[tuple[str, ...], Candidate]
    corrected: Candidate
    fit: dict[str, dict[str, float]]
    noise_floor: float
    witness: float  # share of the hybrid network's learned error the named terms account for


def _test_rmse(candidate: Candidate, samples: Samples, split: Split) -> float:
    return rmse(candidate.fit.model, samples, split.test)


def _fit_table(samples, split, base: Candidate, corrected: Candidate, hybrid: HybridTwin) -> dict:
    return {
        "base": {"val_rmse": base.val_rmse, "test_rmse": _test_rmse(base, samples, split)},
        "corrected": {"val_rmse": corrected.val_rmse, "test_rmse": _test_rmse(corrected, samples, split)},
        "hybrid": {"val_rmse": rmse_of(hybrid, samples, split.val), "test_rmse": rmse_of(hybrid, samples, split.test)},
    }


def _explained_fraction(network: torch.Tensor, named: torch.Tensor) -> float:
    """How much of what the network learned the named terms account for: 1 − ‖Y1 − Δ‖²/‖Y1‖²."""
    return 1.0 - (network - named).square().sum().item() / max(network.square().sum().item(), 1e-300)


def _left_out_entry(term: str, chosen: tuple[str, ...], c: _Context, confounds: list[dict]) -> dict:
    """The contract's ``left_out`` item of one named term, with its evidence in words."""
    corrected = c.corrected
    without = c.candidates.get(tuple(t for t in chosen if t != term), c.candidates[()])
    gain = _test_rmse(without, c.samples, c.split) / c.fit["corrected"]["test_rmse"]
    warnings = []
    for name, value in corrected.fit.params[term].items():
        std = corrected.fit.param_std[term][name]
        if not math.isfinite(std) or abs(std) > POORLY_IDENTIFIED * abs(value):
            warnings.append(f"{name} is poorly identified (std {std:.2g})")
        if abs(corrected.fit.correlation_with_permeability[term][name]) > CORRELATED:
            warnings.append(f"{name} is strongly correlated with K")
    evidence = (
        f"With {term} refitted jointly with K, the BIC falls by {without.fit.bic - corrected.fit.bic:.0f} and the "
        f"validation RMS from {without.val_rmse * 1e9:.3g} to {corrected.val_rmse * 1e9:.3g} nN "
        f"({corrected.val_rmse / c.noise_floor:.2f}× the noise floor); the named terms account for "
        f"{100 * c.witness:.0f}% of the error the hybrid network learned."
    )
    others = [group for group in confounds if term in group["terms"][0]]
    if others:
        evidence += " Confounded with " + ", ".join(group["terms"][1] for group in others) + "."
    if warnings:
        evidence += " Warning: " + "; ".join(warnings) + "."
    return {
        "term": term,
        "params": corrected.fit.params[term],
        "param_std": corrected.fit.param_std[term],
        "evidence": evidence,
        "test_rmse_gain": gain,
    }


def summarise(d: Diagnosis, apparent: ApparentPermeability, threshold: float) -> str:
    """One sentence a person can read."""
    ratio = d.fit["base"]["val_rmse"] / d.noise_floor
    if not d.detected:
        return (
            f"The base model explains every curve to the noise floor (validation RMS {ratio:.2f}× the noise "
            f"floor, residual whiteness {d.whiteness['base']:.1f} ≤ {threshold:g})."
        )
    curves = ", ".join(m.curve for m in d.where) or "the curves"
    lo = min((m.depth_from for m in d.where), default=math.nan) * 1e6
    hi = max((m.depth_to for m in d.where), default=math.nan) * 1e6
    worst = max((m.rms_residual / m.noise_floor for m in d.where), default=ratio)
    sentence = (
        f"{curves} disagree with the base model between {lo:.2f} and {hi:.2f} µm, up to {worst:.1f}× the noise "
        f"floor (whiteness {d.whiteness['base']:.0f}); the plateau permeability changes with speed by "
        f"{apparent.slope:.2g} m² per decade ({apparent.slope_significance:.1f} standard errors). "
    )
    if d.unexplained:
        return sentence + "No term of the vocabulary explains the residual: the hybrid network's correction is kept."
    names = " and ".join(entry["term"] for entry in d.left_out)
    return sentence + (
        f"The base model left out {names}: with it the validation RMS falls to "
        f"{d.fit['corrected']['val_rmse'] / d.noise_floor:.2f}× the noise floor."
    )
