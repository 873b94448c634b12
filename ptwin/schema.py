"""Hydra schema: dataclasses registered in the ConfigStore, so that a typo or a wrong
type fails at the command line. Only entry points (train.py, the CLIs) import this."""

from __future__ import annotations

from dataclasses import dataclass, field

from hydra.core.config_store import ConfigStore

from ptwin.fitting.hybrid_training import HybridSettings
from ptwin.pgd.config import PGDConfig


@dataclass
class DataConfig:
    path: str = "data/demo"
    smoothing: float = 0.05  # velocity window, fraction of a curve's samples


@dataclass
class ModelConfig:
    inputs: list[str] = field(default_factory=lambda: ["depth", "base_speed"])
    hidden: int = 6
    activation: str = "sigmoid"
    self_consistent: bool = True  # False: the paper's purely elastic reference curve
    elastic_nodes: int = 200


@dataclass
class PointwiseConfig:
    iterations: int = 40
    plateau_from: float = 0.5  # fraction of a curve's depth where its K plateau starts


@dataclass
class PhysicsFitConfig:
    iterations: int = 60


@dataclass
class OptimConfig:
    pointwise: PointwiseConfig = field(default_factory=PointwiseConfig)
    physics_fit: PhysicsFitConfig = field(default_factory=PhysicsFitConfig)
    hybrid: HybridSettings = field(default_factory=HybridSettings)


@dataclass
class SplitConfig:
    mode: str = "random"  # or "curve": hold out a whole speed
    fractions: list[float] = field(default_factory=lambda: [0.70, 0.15, 0.15])
    held_out_curve: str | None = None


@dataclass
class DiagnosisConfig:
    enabled: bool = True
    terms: list[str] = field(
        default_factory=lambda: [
            "solid_viscosity",
            "solid_relaxation",
            "pore_pressure_relaxation",
            "strain_dependent_permeability",
            "cantilever_drag",
            "contact_offset",
        ]
    )
    max_terms: int = 2
    bic_margin: float = 10.0  # a term stays only if removing it costs at least this much BIC
    heldout_margin: float = 0.10  # ... and at least this fraction of the validation RMS
    block: int = 50  # samples per block of the whiteness test
    whiteness_threshold: float = 5.0  # block statistic above which a residual is structure, not noise


def register() -> None:
    store = ConfigStore.instance()
    for group, node in (
        ("pgd", PGDConfig),
        ("data", DataConfig),
        ("model", ModelConfig),
        ("optim", OptimConfig),
        ("split", SplitConfig),
        ("diagnosis", DiagnosisConfig),
    ):
        store.store(group=group, name="schema", node=node)
