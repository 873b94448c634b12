"""Synthetic force maps: a grid of spots, each a recording set of ``simulate``, with K and E* varying
smoothly over the map and vocabulary terms concealed inside a disc. The truth, spot by spot, is a
table written beside the map (never inside it)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from ptwin.data.recordings import write_recordings
from ptwin.synth.simulator import Experiment, simulate


@dataclass(frozen=True)
class MapLayout:
    """The grid, how K and E* vary over it, and the disc where ``region_effects`` act (SI units).

    K and E* vary as exp(±``variation``/2) and 1 ± ``variation``/2 across the map (K along x + y, E*
    along x − y), around the experiment's values; the disc is centred on the map by default.
    """

    columns: int
    rows: int
    spacing: float = 5e-6  # [m] between neighbouring spots
    variation: float = 0.4  # relative change of K and E* from one corner to the other
    region_effects: dict[str, dict[str, float]] = field(default_factory=dict)
    region_centre: tuple[float, float] | None = None  # [m]; default: the map's centre
    region_radius: float | None = None  # [m]; default: 0.3 of the map's larger side

    def __post_init__(self):
        if self.columns < 1 or self.rows < 1:
            raise ValueError(f"--map {self.columns} {self.rows}: a map has at least one column and one row")
        if self.spacing <= 0 or not 0 <= self.variation < 2:
            raise ValueError("--spacing must be > 0 and --variation within [0, 2)")

    def spots(self, experiment: Experiment) -> pd.DataFrame:
        """The truth: spot, x, y [m], permeability [m²], effective_modulus [Pa], in_region, per spot."""
        row, column = np.divmod(np.arange(self.rows * self.columns), self.columns)
        x, y = column * self.spacing, row * self.spacing
        u = column / max(self.columns - 1, 1) - 0.5  # −½ … ½ across the map
        v = row / max(self.rows - 1, 1) - 0.5
        width, height = (self.columns - 1) * self.spacing, (self.rows - 1) * self.spacing
        cx, cy = self.region_centre or (width / 2, height / 2)
        radius = self.region_radius if self.region_radius is not None else 0.3 * max(width, height, self.spacing)
        return pd.DataFrame(
            {
                "spot": [f"spot_{r:03d}_{c:03d}" for r, c in zip(row, column)],
                "x": x,
                "y": y,
                "permeability": experiment.permeability * np.exp(self.variation * (u + v) / 2),
                "effective_modulus": experiment.effective_modulus * (1 + self.variation * (u - v) / 2),
                "in_region": np.hypot(x - cx, y - cy) <= radius,
            }
        )


def write_map(out: Path, truth: Path, experiment: Experiment, layout: MapLayout) -> pd.DataFrame:
    """Write the map (one recording set per spot, ``position`` in each meta.yaml) into ``out`` and its truth
    table to ``truth`` (CSV); the noise of spot i is drawn with seed ``experiment.seed + i``."""
    table = layout.spots(experiment)
    inside = {**experiment.effects, **layout.region_effects}
    table["effects"] = [";".join(sorted(inside if spot else experiment.effects)) for spot in table["in_region"]]
    for i, spot in enumerate(table.itertuples()):
        effects = inside if spot.in_region else experiment.effects
        at_spot = replace(
            experiment,
            permeability=float(spot.permeability),
            effective_modulus=float(spot.effective_modulus),
            effects=effects,
            seed=experiment.seed + i,
        )
        meta, curves = simulate(at_spot)
        write_recordings(out / spot.spot, replace(meta, position=(float(spot.x), float(spot.y))), curves)
    truth.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(truth, index=False, float_format="%.9g")
    return table
