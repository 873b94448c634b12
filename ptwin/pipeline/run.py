"""The whole chain on one recording set: prepare → identify → hybrid twin → diagnose → report."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np
import torch

from ptwin.data.kinematics import CurveKinematics
from ptwin.data.noise import (
    RESIDUAL,
    NoiseModel,
    corrected,
    difference_factor,
    residual_noise,
    rests_on_short_records,
)
from ptwin.diagnosis.design import ExperimentDesign
from ptwin.diagnosis.diagnose import Diagnosis, DiagnosisSettings, FirstFits, Weighed, diagnose, first_fits, weigh
from ptwin.diagnosis.name import Candidate
from ptwin.fitting.hybrid import HybridTwin
from ptwin.fitting.inflation_range import InflationRange, recorded
from ptwin.fitting.physics_fit import PhysicsFit
from ptwin.physics.samples import Samples
from ptwin.physics.terms import VOCABULARY
from ptwin.pipeline.drawing import Drawing
from ptwin.pipeline.identify import Identification, identify, per_curve_fits
from ptwin.pipeline.prepare import Prepared, fitted_samples, prepare
from ptwin.pipeline.settings import Settings
from ptwin.pipeline.twin import TwinAside
from ptwin.reporting.figures import diagnosis_figures, in_paper_order, proposal_figures, stage_figures
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
from ptwin.reporting.tensorboard import write_summary
from ptwin.threads import one_thread

# Without a hybrid twin (a map's spots), the base model's residual in contact less a polynomial of this degree in
# time per curve stands in for the twin's: about as flexible over a curve as its 6 neurons, it takes a term's
# smooth force out and leaves the noise's correlation at 50-sample blocks (a bend every ~140 samples of a
# 950-sample contact). The 3×36-sample baselines of the bench map's spots gave κ² from 1 to 44 on white noise,
# resting on 2 blocks, their pore relaxation unnamed at 6 of 60 spots; this residual gives 1.0–15 (median 2.0:
# it carries the elastic law's inherited noise, which the structure test's null holds too) on 38 blocks.
FLEXIBLE_DEGREE = 6
# A σ read off second differences that the twin's residual says may read this many times low gets a note: its χ²
# would be 1.44× the noise's, beyond what the structure test's model error tolerates.
LOW_STD = 1.2
CAPPED = "its correlation capped by what a model's residual in contact shows (a line removed per curve)"
READ_UNDER = "the fits so far read under it (no decision on the way to them turns between the two readings)"
FITTED_UNDER = "the fits so far made again under it"
LARGER = "capped by a larger subset's residual"
BASE_RESIDUAL = (
    f"base model's residual in contact, less a polynomial of degree {FLEXIBLE_DEGREE} in time per curve "
    "(no baseline of 100 samples)"
)


@dataclass
class RunResult:
    results: dict  # results.json
    diagnosis: dict  # diagnosis.json
    figures: dict  # {name: its PNG file}
    candidates: dict[str, dict[str, float] | None]  # each term the diagnosis fitted → its values fitted alone
    # (None: that fit failed); the others were no candidates for this set
    base_permeability: float | None = None  # the diagnosis's base model's K as its fit found it [m²] (diagnosis.json
    # leaves a K without fluid force null; its words need the value)
    alone: dict = field(default_factory=dict)  # ``Diagnosis.alone``: the profiled terms' strengths' intervals


@one_thread()
def run(settings: Settings, output_dir: Path, progress: Callable[[str], None] = print) -> RunResult:
    """Run the chain for ``settings`` and leave its results in ``output_dir``, on one thread (``ptwin.threads``)."""
    started = time.perf_counter()
    torch.manual_seed(settings.seed)
    output_dir.mkdir(parents=True, exist_ok=True)
    prepared = prepare(settings, progress)
    samples, split = prepared.samples, prepared.split
    identification = identify(prepared, settings.optim, progress)
    noise = prepared.noise_floor

    draw = partial(_stage_figures, output_dir, prepared, identification) if settings.figures else None
    twin_aside = TwinAside(prepared, identification.base.permeability, noise, settings, output_dir, progress, draw)
    with twin_aside as aside, Drawing() as corrected_figures:

        def draw_corrected(chosen: tuple[str, ...], corrected: PhysicsFit) -> None:
            iterations = settings.optim.physics_fit.iterations
            twin = aside.twin()
            corrected_figures.start(
                partial(_corrected_figures, output_dir, prepared, identification, twin, iterations, chosen, corrected)
            )

        on_chosen = draw_corrected if settings.figures else None
        diagnosis = diagnose_set(prepared, identification, aside.twin, settings, progress, on_chosen)
        outcome = aside.outcome()
        figures = {}
        if settings.figures:
            taken = {**aside.drawn(), **corrected_figures.figures(progress)}
            figures = in_paper_order({**taken, **proposal_figures(output_dir, diagnosis.predictions, progress)})
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
    metrics = {"hparam/val_rmse": hybrid["val_rmse"], "hparam/test_rmse": hybrid["test_rmse"]}
    write_summary(output_dir / "tensorboard", figures, hparams, metrics)
    payload = write_outputs(output_dir, results, diagnosis, figures)
    print_summary(results, payload, progress, diagnosis.permeability)
    progress(f"results in {output_dir} ({results['seconds']:.1f} s)")
    tried = {term: _alone(diagnosis, term) for term in VOCABULARY if any(term in key for key in diagnosis.candidates)}
    return RunResult(results, payload, figures, tried, diagnosis.permeability["base"], diagnosis.alone)


def _stage_figures(
    output_dir: Path, prepared: Prepared, identification: Identification, twin: HybridTwin, say: Callable[[str], None]
) -> dict:
    """The figures of stages 1–3, which the diagnosis does not change: drawn aside beside it (``TwinAside``)."""
    return stage_figures(output_dir, prepared.samples, prepared.split, identification, twin, prepared.rate, say)


def _corrected_figures(
    output_dir: Path,
    prepared: Prepared,
    identification: Identification,
    twin: HybridTwin,
    iterations: int,
    chosen: tuple[str, ...],
    corrected: PhysicsFit,
    say: Callable[[str], None],
) -> dict:
    """The figures of the corrected model: drawn aside while the diagnosis finds its intervals."""
    per_curve = _corrected_per_curve(prepared, chosen, corrected.params, iterations)
    samples, split = prepared.samples, prepared.split
    return diagnosis_figures(output_dir, samples, split, identification, twin, chosen, corrected.model, per_curve, say)


def _alone(diagnosis: Diagnosis, term: str) -> dict[str, float] | None:
    """``term``'s values fitted alone beside the base model, physical or not (None: not fitted alone, or failed)."""
    alone = diagnosis.candidates.get((term,))
    return alone.fit.params[term] if alone is not None and alone.fit is not None else None


def diagnose_set(
    prepared: Prepared,
    identification: Identification,
    twin: Callable[[], HybridTwin] | None,
    settings: Settings,
    progress: Callable[[str], None] = print,
    on_chosen: Callable[[tuple[str, ...], PhysicsFit], None] | None = None,
) -> Diagnosis:
    """The diagnosis stage on a prepared and identified set (``twin``: the hybrid twin when asked for, None where
    none is trained; ``on_chosen``: as ``diagnose``'s). Where the set's baselines were too short to measure the
    noise's correlation, it is measured on the twin's residual in contact (``ptwin.data.noise.residual_noise``), or
    without a twin on the base model's less a polynomial per curve (``FLEXIBLE_DEGREE``), whose σ the base model is
    refitted under. The base model and each single term are fitted first (``first_fits``) under the reading then at
    hand: before the twin is asked for, so one training aside (``TwinAside``) goes on meanwhile. Where the baselines
    or the twin's residual measured the correlation, a reading above what those fits' residuals show is capped
    (``_capped_by_residuals``): what the twin misses of a term reads as correlation as a baseline's drift does (a
    pore relaxation with a hold and a creep, white noise: κ² 18.0 off the twin's residual, 1.23 capped). A fit's
    optimum never reads κ², so the first fits are read under the reading that stands, or made again where a decision
    on the way to them turns between the two (``ptwin.fitting.inflation_range``). The subsets weighed then cap it once
    more: where each term alone leaves structure, so does its residual, and only the pair that is there reads the
    noise's (a viscosity beside a strain-dependent K in p07's setting: κ² 44 off the baselines, 46–47 off every single
    term's residual, 25 off the pair's, where the noise's is 15.6; under 44 nothing was named)."""
    block, base_fit = settings.diagnosis.block, identification.base
    # read off the base model's residual, σ is corrected by it (no twin): the fits follow it
    measured = _on_base_residual(prepared, base_fit, block) if twin is None else None
    if measured is not None:
        prepared, base_fit = measured, None
    candidates, notes = candidate_settings(prepared, settings)
    fits = _Fits(candidates, settings.optim.physics_fit.iterations, progress)
    with recorded() as span:
        first = fits.first(prepared, {} if base_fit is None else {(): base_fit})
    if base_fit is not None:  # stage 1's, made before: its own range, or none where it was not recorded
        span = span & (identification.base_range or InflationRange(low=math.inf))
    if twin is not None:  # off the twin's residual σ stays the baselines' and only κ² changes
        measured = _on_twin_residual(prepared, twin, block)
        notes += _uncorrected_std(measured) if measured is not None else []
    read = measured or prepared
    # σ corrected by the base model's residual stays together with its κ²: no cap there
    cappable = twin is not None or measured is None
    stands = (_capped_by_residuals(read, first.candidates, block) if cappable else None) or read
    if stands is not prepared:
        source = "capped by a model's residual" if stands is not read else "off the hybrid twin's residual"
        kept = _read_under(stands.noise.inflation, first.candidates, span, source, progress)
        prepared = stands
        with recorded() as again:
            first = fits.first(prepared, kept or {})
        span = span & again if kept is not None else again
    hybrid = twin() if twin is not None else None
    with recorded() as weighing:
        weighed = fits.weighed(prepared, first, hybrid)
    lower = _capped_by_residuals(prepared, weighed.candidates, block) if cappable else None
    if lower is not None:  # a larger subset's residual shows less (a pair of terms, where each alone leaves structure)
        kept = _read_under(lower.noise.inflation, weighed.candidates, span & weighing, LARGER, progress)
        prepared = lower
        weighed = fits.weighed(prepared, fits.first(prepared, kept or {}), hybrid, kept)
    model, samples, split, noise = prepared.make_model, prepared.samples, prepared.split, prepared.noise
    design = _design(prepared, settings) if settings.diagnosis.design else None
    apparent = identification.apparent
    return diagnose(
        model, samples, split, hybrid, apparent, candidates, noise, weighed, progress, notes, design, on_chosen
    )


@dataclass(frozen=True)
class _Fits:
    """How a set's candidate subsets are fitted: the settings ``candidates``, LM steps, where progress goes."""

    candidates: DiagnosisSettings
    iterations: int
    progress: Callable[[str], None]

    def first(self, prepared: Prepared, fitted: dict[tuple[str, ...], PhysicsFit]) -> FirstFits:
        """``first_fits`` on ``prepared`` (``fitted``: fits already made, reused)."""
        model, samples, split, noise = prepared.make_model, prepared.samples, prepared.split, prepared.noise
        s, steps, say = self.candidates, self.iterations, self.progress
        return first_fits(model, samples, split, s, steps, noise, model.reference, fitted, say)

    def weighed(
        self, prepared: Prepared, first: FirstFits, hybrid: HybridTwin | None, fitted: dict | None = None
    ) -> Weighed:
        """``weigh`` on ``prepared`` after ``first`` (``fitted``: fits of larger subsets already made, reused)."""
        model, samples, split, noise = prepared.make_model, prepared.samples, prepared.split, prepared.noise
        s, steps, say = self.candidates, self.iterations, self.progress
        return weigh(model, samples, split, hybrid, s, steps, noise, first, say, fitted)


def _read_under(
    inflation: float,
    fitted: dict[tuple[str, ...], Candidate],
    span: InflationRange,
    source: str,
    progress: Callable[[str], None],
) -> dict[tuple[str, ...], PhysicsFit] | None:
    """The candidates ``fitted`` read under a noise of κ² ``inflation``, where every decision on the way to them
    goes the same way there (``span``); None where they must be made again (``source``: where the reading came
    from, for ``progress``)."""
    reread = span.holds(inflation)
    progress(f"the noise's block inflation is {inflation:.3g} ({source}): {READ_UNDER if reread else FITTED_UNDER}")
    return {s: c.fit.under(inflation) for s, c in fitted.items() if c.fit is not None} if reread else None


def _on_twin_residual(prepared: Prepared, twin: Callable[[], HybridTwin], block: int) -> Prepared | None:
    """``prepared`` under the correlation of the twin's residual (``_residual_noise``, a line removed), or None.
    σ stays the baselines': what the twin leaves of a term is slow and reads as correlation (the demo's white
    noise: κ² 1.86, and 9.1 from a twin that stalled), which would correct a second-difference σ upwards
    (``_uncorrected_std`` says where it may read low)."""
    noise = _residual_noise(prepared, lambda samples: twin().predict(samples), block, 1, RESIDUAL)
    return None if noise is None else _rebuilt(prepared, prepared.fitted, noise)


def _uncorrected_std(prepared: Prepared) -> list[str]:
    """A note where a σ read off second differences stays uncorrected (``_on_twin_residual``) and the twin's residual
    is correlated enough that, were its correlation the noise's, that σ would read more than ``LOW_STD`` times low
    (a null set of AR(1) noise, ρ₁ 0.9, 3 × 36 baseline samples: 3.9×, the truth 3.8×, and "unexplained"). What the
    twin misses adds to that correlation, so the figure is a bound, not a correction."""
    read = [c.curve for c in prepared.curves if c.noise.differences is not None]
    factor = difference_factor(prepared.noise)
    if not read or factor < LOW_STD:
        return []
    return [
        f"The noise std of {', '.join(read)} is read off second differences, which correlated noise makes read low: "
        f"were the noise as correlated as the hybrid twin's residual (lag-1 {prepared.noise.lag1:.2f}), it would "
        f"read {factor:.2g}× low and every χ² here {factor**2:.2g}× high. What the twin misses adds to that "
        "correlation, so this is a bound; a noise_std in meta.yaml, or 100 baseline samples a curve, settles it."
    ]


def _on_base_residual(prepared: Prepared, base_fit: PhysicsFit, block: int) -> Prepared | None:
    """``prepared`` under the correlation of the base model's residual less a polynomial per curve
    (``FLEXIBLE_DEGREE``), or None; every σ read off second differences corrected for it, the reference's too:
    the law inherits its noise, which the structure test's null draws at that σ (left at a second-difference σ,
    8×8 null maps of AR(1) noise of ρ₁ 0.9 read 10 of 64 spots as structure; 1 of 64 corrected)."""
    noise = _residual_noise(prepared, base_fit.model, block, FLEXIBLE_DEGREE, BASE_RESIDUAL)
    if noise is None:
        return None
    law = prepared.make_model.reference
    law.noise_std = corrected(next(c.noise for c in prepared.curves if c.curve == law.curve), noise).std
    return _rebuilt(prepared, [replace(c, noise=corrected(c.noise, noise)) for c in prepared.fitted], noise)


def _capped_by_residuals(
    prepared: Prepared, candidates: dict[tuple[str, ...], Candidate], block: int
) -> Prepared | None:
    """``prepared`` with the correlation its baselines (or the twin's residual) gave capped by what a model's residual
    in contact shows, or None where no residual shows less. A residual holds the noise, the elastic law's inherited
    noise and whatever the model misses, so its block inflation reads the noise's or more: the least over the usable
    ``candidates`` (a line removed per curve) bounds the noise's from above,
    on records ten times the baselines' (p07-like sets, four baselines of 160 samples of AR(1) noise of 20-sample
    memory, 40% white: κ² 5.2–40 from the baselines, 16.7–24 from the residuals, 15.6 the noise's). A curve's own κ² is
    capped by its own residual's the same way. κ² is then the lesser of the two readings; the ν blocks the tests rest on
    stay the baselines'."""
    std, best, residuals = prepared.noise.std, None, []
    for candidate in candidates.values():
        if not candidate.usable:
            continue
        records, step = _contact_records(prepared.samples, candidate.fit.model)
        noise = residual_noise(records, std, step, block, 1, CAPPED)
        if noise is None:
            continue
        residuals.append(records)
        if best is None or noise.inflation < best.inflation:
            best = noise
    if best is None or best.inflation >= prepared.noise.inflation:
        return None
    own = {}  # each curve's least κ² over the residuals
    for records in residuals:
        for curve_id, record in zip(prepared.samples.curve_ids, records):
            alone = residual_noise([record], std, step, block, 1, CAPPED)
            if alone is not None:
                own[curve_id] = min(own.get(curve_id, np.inf), alone.inflation)
    noise = replace(
        prepared.noise,
        share=best.share,
        memory=best.memory,
        lag1=best.lag1,
        inflation=best.inflation,
        correlation_time=best.correlation_time,
        source=prepared.noise.source if CAPPED in prepared.noise.source else f"{prepared.noise.source}, {CAPPED}",
    )
    fitted = [
        replace(c, noise=replace(c.noise, inflation=min(c.noise.inflation, own.get(c.curve, np.inf))))
        for c in prepared.fitted
    ]
    return _rebuilt(prepared, fitted, noise)


def _rebuilt(prepared: Prepared, fitted: list[CurveKinematics], noise: NoiseModel) -> Prepared:
    device = prepared.samples.time.device
    samples, noise = fitted_samples(fitted, noise, device, prepared.reference, prepared.noise_gain)
    return replace(prepared, samples=samples, noise=noise, fitted=fitted)


def _residual_noise(
    prepared: Prepared, predict: Callable[[Samples], torch.Tensor], block: int, degree: int, source: str
) -> NoiseModel | None:
    """The noise's correlation measured on the residual in contact of a model's ``predict``, less a polynomial of
    ``degree`` in time per curve (``source`` says which), where the baselines could not give it
    (``rests_on_short_records``); None where they could, or no curve has a record long enough. The samples are
    rebuilt under it by ``_rebuilt`` (``Samples.from_curves``: a curve whose own baseline measured more keeps its
    own κ² for the whiteness test)."""
    if not rests_on_short_records(prepared.noise):
        return None
    records, step = _contact_records(prepared.samples, predict)
    return residual_noise(records, prepared.noise.std, step, block, degree, source)


def _contact_records(samples: Samples, predict: Callable[[Samples], torch.Tensor]) -> tuple[list[np.ndarray], float]:
    """(each curve's residual of ``predict`` on its samples in contact [N], the sampling step [s])."""
    with torch.no_grad():
        records = [r.cpu().numpy() for r in samples.in_contact_by_curve(predict(samples) - samples.force)]
    return records, float(np.median(np.diff(samples.time[samples.curve == 0].cpu().numpy())))


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
    curves, reference = prepared.curves, prepared.reference
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
        noise_gain=prepared.noise_gain,
    )


def _corrected_per_curve(prepared: Prepared, chosen: tuple[str, ...], values: dict, iterations: int):
    """K per curve with the terms ``chosen`` frozen at their global ``values``, for figure 5 (None when nothing was
    named)."""
    if not chosen:
        return None
    samples, train = prepared.samples, prepared.split.train
    return per_curve_fits(prepared.make_model, samples, train, chosen, iterations, False, values)


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
