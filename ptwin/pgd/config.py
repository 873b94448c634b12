"""Typed settings of a PGD basis build; their hash keys the on-disk cache."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field

from ptwin.checks import refuse_outside


@dataclass
class EnrichmentSettings:
    """Stopping and fixed-point controls of the greedy enrichment (``ptwin.pgd.enrichment``)."""

    max_modes: int = 150
    amplitude_tol: float = 1e-5
    output_tol: float = 1e-7
    fixed_point_tol: float = 1e-8
    max_fixed_point_iterations: int = 25
    seed: int = 0

    def __post_init__(self):
        rules = [
            ("max_modes", self.max_modes >= 1, "1 or more, e.g. 150"),
            ("amplitude_tol", self.amplitude_tol >= 0.0, "0 or more, e.g. 1e-5"),
            ("output_tol", self.output_tol >= 0.0, "0 or more, e.g. 1e-7"),
            ("fixed_point_tol", self.fixed_point_tol >= 0.0, "0 or more, e.g. 1e-8"),
            ("max_fixed_point_iterations", self.max_fixed_point_iterations >= 1, "1 or more, e.g. 25"),
        ]
        refuse_outside(self, rules, "pgd.enrichment.{}".format)


@dataclass
class Grid:
    """A log-uniform grid of one parameter [SI units]."""

    minimum: float
    maximum: float
    nodes: int


@dataclass
class PlaneMesh:
    """The in-plane unit-disc mesh (see ``ptwin.pgd.mesh.unit_disc``)."""

    rings: int = 16
    ring_density: float = 6.58
    edge_grading: float = 1.0

    def __post_init__(self):
        rules = [
            ("rings", self.rings >= 1, "1 or more, e.g. 16"),
            ("ring_density", self.ring_density > 0.0, "positive, e.g. 6.58"),
            ("edge_grading", self.edge_grading > 0.0, "positive (1: rings evenly spaced), e.g. 1.0"),
        ]
        refuse_outside(self, rules, "pgd.plane.{}".format)


@dataclass
class ThicknessMesh:
    """The φ mesh, graded toward the loaded top; ``finest`` is the top element."""

    nodes: int = 300
    finest: float = 1.0e-8

    def __post_init__(self):
        rules = [
            ("nodes", self.nodes >= 3, "3 or more, e.g. 300"),
            ("finest", 0.0 < self.finest < 1.0, "the top element's thickness, between 0 and 1, e.g. 1.0e-8"),
        ]
        refuse_outside(self, rules, "pgd.thickness.{}".format)


@dataclass
class PGDConfig:
    """Everything that determines a basis. ``coordinates``: "scaled" (aspect ratio
    H/R as the extra coordinate, converges) or "paper" (R and H separated, stalls).
    ``richardson``: also build on the mesh with half the rings and extrapolate the
    force with ``richardson_order`` (the ``precise`` preset)."""

    coordinates: str = "scaled"
    plane: PlaneMesh = field(default_factory=PlaneMesh)
    thickness: ThicknessMesh = field(default_factory=ThicknessMesh)
    velocity: Grid = field(default_factory=lambda: Grid(1.0e-8, 5.0e-4, 41))
    permeability: Grid = field(default_factory=lambda: Grid(1.0e-19, 1.0e-13, 61))
    contact_radius: Grid = field(default_factory=lambda: Grid(1.0e-7, 5.0e-5, 61))
    height: Grid = field(default_factory=lambda: Grid(1.0e-6, 1.0e-2, 161))
    aspect_ratio: Grid = field(default_factory=lambda: Grid(0.1, 1.0e5, 241))
    enrichment: EnrichmentSettings = field(default_factory=EnrichmentSettings)
    richardson: bool = False
    richardson_order: float = 2.0

    def __post_init__(self):
        if self.coordinates not in ("scaled", "paper"):
            raise ValueError(f"pgd.coordinates must be 'scaled' or 'paper', got {self.coordinates!r}")
        for name in ("velocity", "permeability", "contact_radius", "height", "aspect_ratio"):
            grid = getattr(self, name)
            if not 0 < grid.minimum < grid.maximum or grid.nodes < 4:
                raise ValueError(f"pgd.{name}: need 0 < minimum < maximum and nodes >= 4, got {grid}")
        rules = [
            ("richardson_order", self.richardson_order > 0.0, "positive, e.g. 2.0"),
            (
                "richardson",
                not self.richardson or self.plane.rings >= 2,
                "false where pgd.plane.rings < 2 (its mesh has half)",
            ),
        ]
        refuse_outside(self, rules, "pgd.{}".format)

    @classmethod
    def from_dict(cls, values: dict) -> PGDConfig:
        grids = {
            k: Grid(**values[k])
            for k in ("velocity", "permeability", "contact_radius", "height", "aspect_ratio")
            if k in values
        }
        nested = {
            "plane": PlaneMesh(**values.get("plane", {})),
            "thickness": ThicknessMesh(**values.get("thickness", {})),
            "enrichment": EnrichmentSettings(**values.get("enrichment", {})),
        }
        plain = {k: v for k, v in values.items() if k not in grids and k not in nested}
        return cls(**plain, **grids, **nested)

    @property
    def shape(self) -> str:
        """The fourth parameter: the aspect ratio H/R (scaled coordinates) or the height H (paper)."""
        return "aspect_ratio" if self.coordinates == "scaled" else "height"

    def to_dict(self) -> dict:
        return asdict(self)

    def hash(self) -> str:
        """sha256 of the canonical JSON of every setting that shapes the basis (the cache key);
        the grid of the coordinate system not in use is left out."""
        unused = "height" if self.coordinates == "scaled" else "aspect_ratio"
        used = {k: v for k, v in self.to_dict().items() if k != unused}
        return hashlib.sha256(json.dumps(used, sort_keys=True).encode()).hexdigest()
