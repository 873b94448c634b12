"""Stage 0: load and check the recording set, its kinematics and noise, the PGD basis,
the split, and the factory every later stage builds its models with."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import cached_property, partial

import numpy as np
import torch

from ptwin.data.evidence import SPOT_VARIATION, RateEffect, drag_from_baselines, rate_effect, spot_variation
from ptwin.data.kinematics import CurveKinematics, curve_kinematics
from ptwin.data.noise import NOTHING, NoiseModel, corrected, pooled
from ptwin.data.recordings import APPROACH, MIN_SAMPLES, Meta, RecordingError, RecordingSet, load_recordings
from ptwin.data.relaxation import Relaxation, relaxations
from ptwin.fitting.hybrid import ErrorNetwork, HybridTwin
from ptwin.fitting.split import Split, split_samples
from ptwin.pgd.basis import Basis
from ptwin.pgd.cache import cached_basis
from ptwin.physics.contact import ContactNuisance
from ptwin.physics.elastic import ReferenceCurve
from ptwin.physics.fluid_force import FluidForce
from ptwin.physics.model import ForceModel
from ptwin.physics.samples import Samples
from ptwin.physics.terms import hidden_in_contacts
from ptwin.pipeline.settings import ModelSettings, Settings


class UnsupportedSet(RecordingError):
    """A valid recording set that cannot support a diagnosis; the message says what to record."""


@dataclass
class ModelFactory:
    """Fresh force models and hybrid twins of one recording set, all on one elastic reference."""

    meta: Meta
    reference: ReferenceCurve
    basis: Basis
    model: ModelSettings
    permeability: float  # starting K [m²]
    device: str
    seed: int
    contact_ids: tuple[str, ...] | None = None  # fitted curves whose contacts are nuisances (estimated)
    reference_onset: float = math.inf  # the reference's ``Baseline.onset`` [m]: how far its correction may go
    root_shifts: dict[str, float] | None = None  # each curve's ``Baseline.root_shift`` [m] (estimated contacts)

    def __call__(
        self, terms: tuple[str, ...] = (), values: dict | None = None, permeability: float | None = None
    ) -> ForceModel:
        """The base model with ``terms`` (starting at ``values``), K = ``permeability`` or the default. With a term
        whose force the contact corrections absorb at first order (``Term.CONTACT_CAVEAT``: it grows as √w from
        contact), they start where the onset read as Hertz beside a √w force puts each contact
        (``Baseline.root_shift``): from the Hertz estimates, the fit starts where the term hides (real PAAm with
        5 Pa·s added: γ −5.9 to −6.4 from each start; from these, γ 5.8)."""
        meta = self.meta
        fluid = self._fluid.at(permeability or self.permeability)
        contact = ContactNuisance(self.contact_ids, self.reference_onset) if self.contact_ids is not None else None
        if contact is not None and self.root_shifts and hidden_in_contacts(terms):
            contact.place(self.root_shifts, self.reference.curve)
        model = ForceModel(
            self.reference,
            fluid,
            meta.probe_radius,
            meta.sample_thickness,
            terms,
            values,
            self.model.self_consistent,
            contact,
        )
        return model.to(self.device)

    @cached_property
    def _fluid(self) -> FluidForce:
        """The basis's fluid layer, built once: every model's is this one's at its own K (``FluidForce.at``)."""
        return FluidForce(self.basis, self.permeability, self.meta.fluid_viscosity)

    def twin(self, permeability: float, force_scale: float, samples: Samples, train: torch.Tensor) -> HybridTwin:
        """A hybrid twin: the base model at K = ``permeability`` next to a seeded error network whose
        inputs are standardised on ``samples[train]`` and whose output is in units of ``force_scale`` [N]."""
        m = self.model
        generator = torch.Generator().manual_seed(self.seed)
        network = ErrorNetwork(m.inputs, m.hidden, m.activation, samples, train, force_scale, generator)
        return HybridTwin(self(permeability=permeability), network.to(self.device))


@dataclass
class Prepared:
    recordings: RecordingSet
    curves: list[CurveKinematics]  # every curve, in file order
    basis: Basis
    samples: Samples  # the non-reference curves: what every stage fits
    split: Split
    make_model: ModelFactory
    noise: NoiseModel  # the set's
    fitted: list[CurveKinematics]  # what ``samples`` holds: the curves as fitted (``_fitted_curves``)
    notes: list[str] = field(default_factory=list)  # evidence about the data, in sentences
    rate: RateEffect | None = None  # F/F_ref at equal depth of the faster approaches
    relaxations: list[Relaxation] = field(default_factory=list)  # what each hold and creep shows before any model

    @property
    def noise_floor(self) -> float:
        """The run's one noise floor [N]: the mean over every fitted sample of its curve's σ."""
        return self.noise.std

    @property
    def noise_gain(self) -> Callable[[np.ndarray], np.ndarray]:
        """Depth [m] → the force noise's gain in a sample's residual there (``ReferenceCurve.noise_gain``)."""
        return partial(self.make_model.reference.noise_gain, spring_constant=self.recordings.meta.spring_constant)

    @property
    def reference(self) -> CurveKinematics:
        """The reference curve, whose approach is the elastic law."""
        return next(c for c in self.curves if c.curve == self.recordings.meta.reference_curve)

    @property
    def estimated_contact(self) -> bool:
        return self.make_model.contact_ids is not None

    @property
    def common_level(self) -> bool:
        """One common baseline level was removed from every curve (drag, if any, is still in the force)."""
        return all(c.baseline is not None and c.baseline.common for c in self.curves)


def prepare(settings: Settings, progress: Callable[[str], None] = print) -> Prepared:
    """Load and check the recordings, print their kinematics, get the cached basis, split."""
    recordings = load_recordings(settings.data.path)
    meta = recordings.meta
    curves = curve_kinematics(recordings, settings.data.smoothing, settings.diagnosis.block)
    _check_noise(recordings, curves)
    noise = pooled(
        [c.noise for c in curves],
        [max(int(c.in_contact.sum()), 1) for c in curves],
        _steps(curves),
        settings.diagnosis.block,
        settings.diagnosis.false_alarm,
    )
    # σ read off second differences, corrected for the set's correlation before the law inherits the reference's
    curves = [replace(c, noise=corrected(c.noise, noise)) for c in curves]
    _print_kinematics(curves, progress)
    reference = next(c for c in curves if c.curve == meta.reference_curve)
    _check_law(recordings, reference)
    law = ReferenceCurve(reference, settings.model.elastic_nodes, settings.model.elastic_smoothing)
    fitted, notes = _fitted_curves(recordings, curves, reference, law)
    notes += [_unsettled_note(c) for c in curves if c.noise.unsettled]
    if recordings.unread:
        keys = ", ".join(recordings.unread)
        notes.append(f"meta.yaml: {keys}: no key of the recording format (v1.2), so not read.")
    gain = partial(law.noise_gain, spring_constant=meta.spring_constant)
    samples, noise = fitted_samples(fitted, noise, settings.device, reference, gain)
    basis = cached_basis(settings.pgd, settings.cache_dir, progress)
    s = settings.split
    try:
        split = split_samples(samples, tuple(s.fractions), s.mode, s.held_out_curve, settings.seed)
    except ValueError as error:  # a held-out curve this set does not fit: the settings are checked on their own
        raise RecordingError(f"{recordings.path}: {error}") from None
    # The reference's contact is the origin of depth: a fitted hold of its own gets no correction.
    contact_ids, onset = None, math.inf
    if meta.contact_point == "estimate":
        contact_ids = tuple(c for c in samples.curve_ids if c != reference.curve)
        onset = reference.baseline.onset
    shifts = {c.curve: c.baseline.root_shift for c in curves if c.baseline is not None} or None
    factory = ModelFactory(
        meta,
        law,
        basis,
        settings.model,
        settings.permeability,
        settings.device,
        settings.seed,
        contact_ids,
        onset,
        shifts,
    )
    rate = rate_effect(curves, reference)
    held = relaxations(curves)
    places = meta.places()
    evidence = (
        f"The import said {places}." if places else None,
        _spot_note(curves),
        drag_from_baselines(curves),
        rate.sentence() if rate else None,
    )
    notes += [sentence for sentence in evidence if sentence] + [r.sentence() for r in held]
    return Prepared(recordings, curves, basis, samples, split, factory, noise, fitted, notes, rate, held)


def _check_noise(recordings: RecordingSet, curves: list[CurveKinematics]) -> None:
    """No curve whose noise reads σ 0 (``ptwin.data.noise.NOTHING``): every χ² would divide by it."""
    silent: dict[str, list[str]] = {}
    for curve in curves:
        if curve.noise.source.startswith(NOTHING):
            silent.setdefault(curve.noise.source.removeprefix(NOTHING), []).append(curve.curve)
    if silent:
        why = "; ".join(f"curve(s) {', '.join(names)}: {reason}" for reason, names in silent.items())
        raise RecordingError(
            f"{recordings.path}: {why}: no noise to judge a fit by (a force simulated without noise, a detector "
            "stuck, smoothed or exported to few digits); export the raw force, leave such a curve out, or set "
            "noise_std in meta.yaml to the instrument's noise [N]"
        )


def _check_law(recordings: RecordingSet, reference: CurveKinematics) -> None:
    """The reference curve's approach in contact is the elastic law: with fewer than ``MIN_SAMPLES`` samples there it
    cannot be read (with none, building it raised IndexError)."""
    count = int(ReferenceCurve.read_from(reference).sum())
    if count < MIN_SAMPLES:
        raise UnsupportedSet(
            f"{recordings.path / 'curves.csv'}: curve {reference.curve!r}, the reference curve, has {count} approach "
            f"samples in contact ({MIN_SAMPLES} at least): its approach is the elastic law; record it into the sample, "
            "or name a curve that indents as reference_curve in meta.yaml"
        )


def _fitted_curves(recordings: RecordingSet, curves, reference, law: ReferenceCurve):
    """The curves every stage fits, and notes on what was left out: every curve but the reference, and of
    the reference what follows its approach (a hold, a creep: the approach is the elastic law), with samples
    in contact no deeper than the law is known (``ReferenceCurve.known_depth``)."""
    after_approach = [c for c in curves if (c.in_contact & (c.segment != APPROACH)).any()]
    speeds = sorted({c.base_speed for c in curves})
    if len(speeds) < 2 and not after_approach:
        raise UnsupportedSet(
            f"{recordings.path}: every curve is at {speeds[0] * 1e6:.3g} µm/s; one speed cannot separate the elastic "
            f"law (read off the slowest curve) from K: record the same spot at two or more speeds, e.g. 3× apart, "
            f"or hold the base still after the approach (stress relaxation)"
        )
    fitted, notes = [], []
    for curve in curves:
        if curve is reference:
            held = curve.in_contact & (curve.segment != APPROACH)
            if not held.any():
                continue
            curve = replace(curve, in_contact=held, pins_contact=np.zeros_like(held))
        # A hold or a creep lies beyond the reference's depth by what the tip creeps on (the law is continued
        # there); an approach deeper than the reference would need a deeper reference.
        known = np.where(curve.segment == APPROACH, law.deepest, law.known_depth)
        beyond = curve.in_contact & (curve.depth > known)
        if beyond.any():
            notes.append(
                f"{curve.curve}: {int(beyond.sum())} samples deeper than the elastic law is known (the reference "
                f"curve's {law.deepest * 1e6:.3g} µm on an approach, {100 * law.CONTINUED:.0f}% more in a hold or "
                f"a creep) are left out of the fits."
            )
            curve = replace(curve, in_contact=curve.in_contact & ~beyond)
        unresolved = curve.in_contact & curve.unresolved
        if unresolved.any():
            first, last = (f"{t:.4g}" for t in (curve.time[unresolved].min(), curve.time[unresolved].max()))
            notes.append(
                f"{curve.curve}: {int(unresolved.sum())} samples where the tip's velocity changes faster than the "
                f"sampling resolves (at {first if first == last else f'{first} to {last}'} s: the rate forces there "
                f"are not fixed by the recording) are left out of the fits."
            )
            curve = replace(curve, in_contact=curve.in_contact & ~unresolved)
        continued = curve.in_contact & (curve.depth > law.deepest)
        if continued.any():
            further = (curve.depth[continued].max() - law.deepest) * 1e9
            notes.append(
                f"{curve.curve}: {int(continued.sum())} samples after the approach lie up to {further:.3g} nm deeper "
                f"than the reference curve reaches; the elastic law is continued there as a sphere's (a line in "
                f"w^1.5 through its deepest {100 * law.TAIL:.0f}%)."
            )
        if curve.in_contact.any():
            fitted.append(curve)
        else:
            notes.append(f"{curve.curve}: no sample in contact within the reference curve's depth; left out.")
    if not fitted:
        raise UnsupportedSet(f"{recordings.path}: no curve besides the reference has samples in contact to fit")
    return fitted, notes


def _unsettled_note(curve: CurveKinematics) -> str:
    """What the noise model left out of a curve's baseline, and why (``ptwin.data.noise.settled``,
    ``level_settled``): nothing is dropped unsaid."""
    return (
        f"{curve.curve}: the first {curve.noise.unsettled} samples of its pre-contact baseline are left out of its "
        f"noise model: they had not settled as the approach began (the cantilever ringing, or the force off the "
        f"baseline's line)."
    )


def _spot_note(curves) -> str | None:
    variation = spot_variation(curves)
    return variation.sentence() if variation is not None and variation.spread > SPOT_VARIATION else None


def fitted_samples(
    fitted: list[CurveKinematics],
    noise: NoiseModel,
    device: str,
    reference: CurveKinematics,
    gain: Callable[[np.ndarray], np.ndarray],
) -> tuple[Samples, NoiseModel]:
    """The ``fitted`` curves' samples under the set's ``noise`` (its κ²), and that noise with σ the curves' mean
    over their fitted samples; ``reference``: the reference curve, whose baseline the law carries; ``gain``: depth
    → the force noise's gain in the residual (``Prepared.noise_gain``)."""
    noise = replace(noise, std=float(np.average([c.noise.std for c in fitted], weights=_counts(fitted))))
    return Samples.from_curves(fitted, noise.inflation, reference, gain).to(device), noise


def _counts(curves) -> list[int]:
    return [int(c.in_contact.sum()) for c in curves]


def _steps(curves) -> list[float]:
    return [float(np.median(np.diff(c.time))) for c in curves]


def _print_kinematics(curves: list[CurveKinematics], progress: Callable[[str], None]) -> None:
    header = ("curve", "speed µm/s", "contact", "max depth µm", "noise nN", "κ²", "offset nN")
    progress(" ".join(f"{title:>{width}s}" for title, width in zip(header, (6, 10, 8, 12, 8, 5, 9))))
    for c in curves:
        offset = "–" if c.baseline_offset is None else f"{c.baseline_offset * 1e9:.3f}"
        progress(
            f"{c.curve:>6s} {c.base_speed * 1e6:10.3g} {int(c.in_contact.sum()):8d} {c.depth.max() * 1e6:12.3f} "
            f"{c.noise.std * 1e9:8.3f} {c.noise.inflation:5.2f} {offset:>9s}"
        )
