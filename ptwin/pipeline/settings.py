"""The typed settings of a run: one dataclass per config group (``configs/<group>/``), and
``Settings`` for the whole of ``configs/train.yaml``. Stages take these, never Hydra's
DictConfig; the faces register them as the configs' schema, so that a misspelt key or a
value of the wrong type fails at the command line."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ptwin.checks import refuse_outside
from ptwin.diagnosis.diagnose import DiagnosisSettings
from ptwin.fitting.hybrid import check_network
from ptwin.fitting.hybrid_training import HybridSettings
from ptwin.fitting.split import check_split
from ptwin.pgd.config import PGDConfig
from ptwin.physics.terms import VOCABULARY


@dataclass
class DataSettings:
    path: str = "data/demo"  # the recording-set folder
    smoothing: float = 0.05  # velocity window, fraction of the approach's samples

    def __post_init__(self):
        refuse_outside(
            self, [("smoothing", 0.0 <= self.smoothing <= 1.0, "a fraction from 0 to 1, e.g. 0.05")], "data.{}".format
        )


@dataclass
class ModelSettings:
    """The force model's elastic law and the hybrid twin's network."""

    inputs: list[str] = field(default_factory=lambda: ["depth", "base_speed"])  # depth, base_speed, velocity, time
    hidden: int = 6
    activation: str = "sigmoid"
    self_consistent: bool = True  # False: the paper's purely elastic reference curve
    elastic_nodes: int = 200  # depth nodes of the elastic law
    elastic_smoothing: float = 0.05  # the law's local-line window, fraction of the reference curve's samples

    def __post_init__(self):
        check_network(self.inputs, self.activation)
        rules = [
            ("hidden", self.hidden >= 1, "1 or more neurons, e.g. the paper's 6"),
            ("elastic_nodes", self.elastic_nodes >= 2, "2 or more depth nodes, e.g. 200"),
            ("elastic_smoothing", 0.0 <= self.elastic_smoothing <= 1.0, "a fraction from 0 to 1, e.g. 0.05"),
        ]
        refuse_outside(self, rules, "model.{}".format)


@dataclass
class PointwiseSettings:
    iterations: int = 40  # Newton steps of stage 1's K(w)
    plateau_from: float = 0.5  # fraction of a curve's depth where its K plateau starts

    def __post_init__(self):
        rules = [
            ("iterations", self.iterations >= 1, "1 or more Newton steps, e.g. 40"),
            ("plateau_from", 0.0 <= self.plateau_from < 1.0, "a fraction of the depth from 0 to below 1, e.g. 0.5"),
        ]
        refuse_outside(self, rules, "optim.pointwise.{}".format)


@dataclass
class PhysicsFitSettings:
    iterations: int = 60  # LM steps of every physics fit (global K, (K, gamma), candidates)

    def __post_init__(self):
        refuse_outside(
            self, [("iterations", self.iterations >= 1, "1 or more LM steps, e.g. 60")], "optim.physics_fit.{}".format
        )


@dataclass
class OptimSettings:
    pointwise: PointwiseSettings = field(default_factory=PointwiseSettings)
    physics_fit: PhysicsFitSettings = field(default_factory=PhysicsFitSettings)
    hybrid: HybridSettings = field(default_factory=HybridSettings)


@dataclass
class SplitSettings:
    mode: str = "random"  # or "curve": hold out a whole curve as the test set
    fractions: list[float] = field(default_factory=lambda: [0.70, 0.15, 0.15])
    held_out_curve: str | None = None  # with mode=curve; default: the fastest

    def __post_init__(self):
        check_split(self.fractions, self.mode)


@dataclass
class Settings:
    """Everything ``python train.py`` runs on."""

    data: DataSettings = field(default_factory=DataSettings)
    pgd: PGDConfig = field(default_factory=PGDConfig)
    model: ModelSettings = field(default_factory=ModelSettings)
    optim: OptimSettings = field(default_factory=OptimSettings)
    split: SplitSettings = field(default_factory=SplitSettings)
    diagnosis: DiagnosisSettings = field(default_factory=DiagnosisSettings)
    seed: int = 0
    device: str = "cpu"
    cache_dir: str = ".cache/ptwin"  # where PGD bases are kept, keyed by their config hash
    ckpt_path: str | None = None  # a checkpoint.pt to resume from
    permeability: float = 2.0e-16  # starting K [m²]
    figures: bool = True  # draw the PNG figures (false: tables, report and diagnosis only; 1.5–2.5 s less a set)

    def __post_init__(self):
        rules = [("permeability", 0.0 < self.permeability < math.inf, "a positive starting K [m²], e.g. 2.0e-16")]
        refuse_outside(self, rules, str)


@dataclass
class MapSettings:
    """How ``python -m ptwin.map`` runs the spots of a force map (the ``map`` config group)."""

    scheduler: str = "local"  # local: a Dask LocalCluster here; serial: in this process; or a scheduler's address
    workers: int = 0  # workers of the local cluster (0: one per core)
    hybrid: bool = False  # train each spot's hybrid twin too (slow; its learned error joins the evidence)

    def __post_init__(self):
        refuse_outside(self, [("workers", self.workers >= 0, "0 or more (0: one per core), e.g. 2")], "map.{}".format)


@dataclass
class MapRunSettings(Settings):
    """Everything ``python -m ptwin.map`` runs on: a spot's settings (``data.path`` is the map's folder)."""

    map: MapSettings = field(default_factory=MapSettings)


EVERY_TERM = "all"  # inject.term: every candidate term, each until named


@dataclass
class InjectSettings:
    """What ``python -m ptwin.inject`` adds to a recording set (the ``inject`` config group): ``term`` with
    ``values``, its parameters in the vocabulary's order (a list, so that an override replaces it whole:
    Hydra merges a dict key by key and refuses another term's keys), scaled by each of ``sizes`` in its
    first parameter (its strength: gamma, g, alpha, m, b; M for the pore term), one diagnosis each.
    ``term: all``: every candidate term instead, each at growing sizes until named (``values`` and ``sizes``
    unused: ``ptwin.pipeline.inject.detection_limits``)."""

    term: str = "solid_viscosity"
    values: list[float] = field(default_factory=lambda: [5.0])
    sizes: list[float] = field(default_factory=lambda: [1.0])

    def __post_init__(self):
        if self.term == EVERY_TERM:
            return
        if self.term not in VOCABULARY:
            raise ValueError(
                f"inject.term {self.term!r} is not in the vocabulary; pick one of {', '.join(VOCABULARY)}, or "
                f"{EVERY_TERM} for each"
            )
        if VOCABULARY[self.term].NOT_INJECTED:
            raise ValueError(f"inject.term {self.term} cannot be added: {VOCABULARY[self.term].NOT_INJECTED}")
        names = list(VOCABULARY[self.term].PARAMS)
        if len(self.values) != len(names):
            raise ValueError(
                f"inject.values of {self.term} are its parameters in the order {names}: give {len(names)}, "
                f"got {list(self.values)}"
            )
        rules = [
            (
                "sizes",
                bool(self.sizes) and min(self.sizes) > 0,
                "positive multiples of the term's strength, e.g. [1, 2]",
            )
        ]
        refuse_outside(self, rules, "inject.{}".format)
        # a force no material has would be found or missed for reasons of its own (a viscosity of -1 Pa s was added)
        params = VOCABULARY[self.term].PARAMS
        for size in self.sizes:
            for name, value in self.scaled(size).items():
                why = params[name].outside(name, value) if math.isfinite(value) else f"{name} is not finite"
                if why:
                    at = f" (inject.sizes {size:g})" if size != 1 else ""
                    raise ValueError(
                        f"inject.values: {name} {value:g}{at} is no physical {self.term} ({why}); give values in its "
                        "physical range, the first times each of inject.sizes"
                    )

    def scaled(self, size: float) -> dict[str, float]:
        """The term's parameters by name, its strength (first parameter) times ``size``."""
        names = list(VOCABULARY[self.term].PARAMS)
        return {name: value * size if i == 0 else value for i, (name, value) in enumerate(zip(names, self.values))}


@dataclass
class InjectRunSettings(Settings):
    """Everything ``python -m ptwin.inject`` runs on: the diagnosis's settings and what to add."""

    inject: InjectSettings = field(default_factory=InjectSettings)
