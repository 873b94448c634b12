"""The whole chain on one recording set: prepare → identify → hybrid twin → diagnose → report."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import torch

from ptwin.data.noise import residual_noise, rests_on_short_records
from ptwin.diagnosis.design import ExperimentDesign
from ptwin.diagnosis.diagnose import Diagnosis, DiagnosisSettings, diagnose
from ptwin.fitting.hybrid import HybridTwin
from ptwin.physics.samples import Samples
from ptwin.physics.terms import VOCABULARY
from ptwin.pipeline.identify import Identification, identify, per_curve_fits
from ptwin.pipeline.prepare import Prepared, prepare
from ptwin.pipeline.settings import Settings
from ptwin.pipeline.twin import train_twin
from ptwin.reporting.figures import figure_file, save_figures
from ptwin.reporting.report import print_summary
from ptwin.reporting.results import (
    apparent_record,
    contact_record,
    hybrid_stage,
    noise_record,
    per_curve_record,
    physics_stage,
    write_outputs,
)
from ptwin.reporting.tensorboard import TrainingLog


@dataclass
class RunResult:
    results: dict  # results.json
    diagnosis: dict  # diagnosis.json
    figures: dict  # {name: matplotlib figure}, each saved as name.png
    candidates: dict[str, dict[str, float] | None]  # each term the diagnosis fitted → its values fitted alone
    # (None: that fit failed); the others were no candidates for this set


def run(settings: Settings, output_dir: Path, progress: Callable[[str], None] = print) -> RunResult:
    """Run the chain for ``settings`` and leave its results in ``output_dir``."""
    started = time.perf_counter()
    torch.manual_seed(settings.seed)
    output_dir.mkdir(parents=True, exist_ok=True)
    prepared = prepare(settings, progress)
    samples, split = prepared.samples, prepared.split
    identification = identify(prepared, settings.optim, progress)
    noise = prepared.noise_floor
    log = TrainingLog(output_dir / "tensorboard", samples, split.train, split.val, noise, settings.optim.hybrid)
    base_k = identification.base.permeability
    outcome = train_twin(prepared, base_k, noise, settings, output_dir, log.on_step, progress)
    log.end_training()
    diagnosis = diagnose_set(prepared, identification, outcome.twin, settings, progress)
    corrected_per_curve = _corrected_per_curve(prepared, diagnosis, settings.optim.physics_fit.iterations)
    figures = save_figures(
        output_dir,
        samples,
        split,
        identification,
        outcome.twin,
        diagnosis,
        corrected_per_curve,
        prepared.rate,
        progress,
    )
    results = _results(prepared, identification, settings)
    results["stages"]["hybrid"] = hybrid_stage(outcome, samples, split, settings.optim.hybrid)
    results["noise_floor"] = noise
    results["seconds"] = time.perf_counter() - started
    hparams = {
        "hidden": settings.model.hidden,
        "activation": settings.model.activation,
        "lambda": outcome.regularisation,
        "seed": settings.seed,
    }
    hybrid = results["stages"]["hybrid"]
    images = {name: figure_file(output_dir, name) for name in figures}
    log.close(images, hparams, {"hparam/val_rmse": hybrid["val_rmse"], "hparam/test_rmse": hybrid["test_rmse"]})
    payload = write_outputs(output_dir, results, diagnosis, figures)
    print_summary(results, payload, progress)
    progress(f"results in {output_dir} ({results['seconds']:.1f} s)")
    tried = {term: _alone(diagnosis, term) for term in VOCABULARY if any(term in key for key in diagnosis.candidates)}
    return RunResult(results, payload, figures, tried)


def _alone(diagnosis: Diagnosis, term: str) -> dict[str, float] | None:
    """``term``'s values fitted alone beside the base model, physical or not (None: not fitted alone, or failed)."""
    alone = diagnosis.candidates.get((term,))
    return alone.fit.params[term] if alone is not None and alone.fit is not None else None


def diagnose_set(
    prepared: Prepared,
    identification: Identification,
    twin: HybridTwin | None,
    settings: Settings,
    progress: Callable[[str], None] = print,
) -> Diagnosis:
    """The diagnosis stage on a prepared and identified set (``twin``: the hybrid twin, None when not trained).
    Where the set's baselines were too short to measure the noise's correlation, it is measured on the twin's
    residual in contact (``ptwin.data.noise.residual_noise``), and the base model refitted under it."""
    measured = _residual_noise(prepared, twin, settings.diagnosis.block) if twin is not None else None
    base_fit = identification.base
    if measured is not None:
        prepared, base_fit = measured, None
    candidates, notes = candidate_settings(prepared, settings)
    return diagnose(
        prepared.make_model,
        prepared.samples,
        prepared.split,
        twin,
        identification.apparent,
        candidates,
        settings.optim.physics_fit.iterations,
        prepared.noise,
        progress,
        base_fit=base_fit,
        notes=notes,
        design=_design(prepared, settings) if settings.diagnosis.design else None,
        reference=prepared.make_model.reference,
    )


def _residual_noise(prepared: Prepared, twin: HybridTwin, block: int) -> Prepared | None:
    """``prepared`` with the noise's correlation measured on ``twin``'s residual in contact, where its baselines
    could not give it (``rests_on_short_records``); None where they could, or no curve has a record long
    enough. The samples are rebuilt with the new κ² (``Samples.from_curves``: a curve whose own baseline
    measured more keeps its own for the whiteness test)."""
    if not rests_on_short_records(prepared.noise):
        return None
    samples = prepared.samples
    with torch.no_grad():
        residual = (twin.predict(samples) - samples.force).cpu().numpy()
    curve, in_contact = samples.curve.cpu().numpy(), samples.in_contact.cpu().numpy()
    records = [residual[(curve == i) & in_contact] for i in range(len(samples.curve_ids))]
    step = float(np.median(np.diff(samples.time.cpu().numpy()[curve == 0])))
    noise = residual_noise(records, prepared.noise.std, step, block)
    if noise is None:
        return None
    samples = Samples.from_curves(prepared.fitted, noise.inflation).to(samples.time.device)
    return replace(prepared, samples=samples, noise=noise)


def candidate_settings(prepared: Prepared, settings: Settings) -> tuple[DiagnosisSettings, list[str]]:
    """The diagnosis settings for this set (with estimated contacts, the terms that are nuisances then
    are no candidates) and the notes on the data, with why a term was not tried."""
    notes = list(prepared.notes)
    terms = settings.diagnosis.terms
    if prepared.estimated_contact:
        skipped = [
            t
            for t in terms
            if VOCABULARY[t].WITH_ESTIMATED_CONTACT
            and not (VOCABULARY[t].KEPT_BY_COMMON_LEVEL and prepared.common_level)
        ]
        notes += [f"{t} is not a candidate: {VOCABULARY[t].WITH_ESTIMATED_CONTACT}." for t in skipped]
        terms = [t for t in terms if t not in skipped]
        notes += [f"{t}: {VOCABULARY[t].CONTACT_CAVEAT}." for t in terms if VOCABULARY[t].CONTACT_CAVEAT]
    return replace(settings.diagnosis, terms=terms), notes


def _design(prepared: Prepared, settings: Settings) -> ExperimentDesign:
    """What the next experiment is proposed for: this set's speeds, depth, sampling, noise and data."""
    curves = prepared.curves
    reference = next(c for c in curves if c.curve == prepared.recordings.meta.reference_curve)
    return ExperimentDesign(
        meta=prepared.recordings.meta,
        speeds=tuple(sorted({c.base_speed for c in curves})),
        depth=float(reference.depth[reference.in_contact].max()),
        noise=prepared.noise,
        step=float(np.median([np.median(np.diff(c.time)) for c in curves])),
        free_travel=float(max(np.median([-c.z[0] for c in curves]), 0.1e-6)),
        make_model=prepared.make_model,
        samples=prepared.samples,
        index=prepared.split.train,
        smoothing=settings.data.smoothing,
        heldout_margin=settings.diagnosis.heldout_margin,
    )


def _corrected_per_curve(prepared: Prepared, diagnosis: Diagnosis, iterations: int):
    """K per curve with the named terms frozen at their global values (None when nothing was named)."""
    if not diagnosis.chosen:
        return None
    values = diagnosis.corrected.fit.params
    samples, train = prepared.samples, prepared.split.train
    return per_curve_fits(prepared.make_model, samples, train, diagnosis.chosen, iterations, False, values)


def _results(prepared: Prepared, identification: Identification, settings: Settings) -> dict:
    """results.json of stages 1–2, the split, the noise and the contacts."""
    samples, split = prepared.samples, prepared.split
    stages = {"elastic_darcy": physics_stage(identification.base, samples, split)}
    if identification.viscous is not None:
        stages["viscous"] = physics_stage(identification.viscous, samples, split)
    term = identification.viscous_term
    return {
        "recordings": str(prepared.recordings.path),
        "basis_hash": prepared.basis.config_hash,
        "split": {"mode": settings.split.mode, "held_out_curve": split.held_out_curve},
        "noise": noise_record(prepared.curves, prepared.noise),
        "contact": contact_record(prepared.curves, identification.base),
        "stages": stages,
        "apparent_permeability": apparent_record(identification.apparent),
        "viscous_per_speed": per_curve_record(identification.viscous_per_curve, term),
        "relaxations": [{**asdict(r), "change": r.change} for r in prepared.relaxations],
    }
