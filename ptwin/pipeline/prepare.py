"""Stage 0: load and check the recording set, its kinematics, the PGD basis, the split,
and the factory every later stage builds its models with."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch

from ptwin.data.kinematics import CurveKinematics, curve_kinematics
from ptwin.data.recordings import Meta, RecordingSet, load_recordings
from ptwin.fitting.hybrid import ErrorNetwork, HybridTwin
from ptwin.fitting.split import Split, split_samples
from ptwin.pgd.basis import Basis
from ptwin.pgd.cache import cached_basis
from ptwin.physics.elastic import ReferenceCurve
from ptwin.physics.fluid_force import FluidForce
from ptwin.physics.model import ForceModel
from ptwin.physics.samples import Samples
from ptwin.pipeline.settings import ModelSettings, Settings


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

    def __call__(
        self, terms: tuple[str, ...] = (), values: dict | None = None, permeability: float | None = None
    ) -> ForceModel:
        """The base model with ``terms`` (starting at ``values``), K = ``permeability`` or the default."""
        meta = self.meta
        fluid = FluidForce(self.basis, permeability or self.permeability, meta.fluid_viscosity)
        model = ForceModel(
            self.reference, fluid, meta.probe_radius, meta.sample_thickness, terms, values, self.model.self_consistent
        )
        return model.to(self.device)

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

    @property
    def noise_floor(self) -> float:
        """The run's one noise floor [N]: the mean over every fitted sample of its curve's."""
        return self.samples.noise_floor[self.samples.in_contact].mean().item()


def prepare(settings: Settings, progress: Callable[[str], None] = print) -> Prepared:
    """Load and check the recordings, print their kinematics, get the cached basis, split."""
    recordings = load_recordings(settings.data.path)
    meta = recordings.meta
    curves = curve_kinematics(recordings, smoothing=settings.data.smoothing)
    progress(
        f"{'curve':>6s} {'speed µm/s':>10s} {'contact':>8s} {'max depth µm':>12s} {'noise nN':>8s} {'offset nN':>9s}"
    )
    for c in curves:
        progress(
            f"{c.curve:>6s} {c.base_speed * 1e6:10.3g} {int(c.in_contact.sum()):8d} {c.depth.max() * 1e6:12.3f} "
            f"{c.noise_floor * 1e9:8.3f} {c.baseline_offset * 1e9:9.3f}"
        )
    basis = cached_basis(settings.pgd, settings.cache_dir, progress)
    reference = next(c for c in curves if c.curve == meta.reference_curve)
    samples = Samples.from_curves([c for c in curves if c is not reference]).to(settings.device)
    s = settings.split
    split = split_samples(samples, tuple(s.fractions), s.mode, s.held_out_curve, settings.seed)
    law = ReferenceCurve(reference, settings.model.elastic_nodes, settings.model.elastic_smoothing)
    factory = ModelFactory(meta, law, basis, settings.model, settings.permeability, settings.device, settings.seed)
    return Prepared(recordings, curves, basis, samples, split, factory)
