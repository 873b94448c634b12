"""The separated basis on disk: modes, grids, config and hash, format version.

Stored through ``ptwin.files`` (atomic, checksummed, a plain dict of tensors and
built-in types loaded with ``weights_only=True``); any other format version is refused.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import torch

from ptwin import files
from ptwin.pgd.compression import SeparatedForce
from ptwin.pgd.config import PGDConfig

FORMAT = "ptwin-pgd-basis/2"


class BasisError(files.StoredFileError):
    """A basis file that cannot be used (wrong version, corrupted, mismatched)."""


@dataclass
class Basis:
    """A built PGD basis: the force over the parameters and the pressure field."""

    config: PGDConfig
    force: SeparatedForce
    grids: dict[str, tuple[float, float, int]]
    field: dict[str, torch.Tensor]
    stats: dict

    @cached_property
    def config_hash(self) -> str:
        """Its config's hash, once: every model a fit builds records it (a basis is read-only once built)."""
        return self.config.hash()

    @classmethod
    def from_build(cls, config, problem, solution, force, stats) -> Basis:
        grids = {}
        for dim in problem.dims.parameters:
            grid = getattr(config, dim.name)
            grids[dim.name] = (grid.minimum, grid.maximum, grid.nodes)
        nodal = [problem.plane_modes @ solution.factors[0], *solution.factors[1:]]  # the plane's eigenbasis to nodes
        field = {
            "plane_nodes": torch.from_numpy(problem.plane_nodes[problem.plane_free]),
            "thickness_nodes": torch.from_numpy(problem.thickness_nodes),
            "amplitudes": solution.amplitudes,
            **{f"factors_{name}": f for name, f in zip(solution.names, nodal)},
        }
        stats = {**stats, "history": solution.history}
        return cls(config, force, grids, field, stats)

    def save(self, path: str | Path) -> None:
        """Write atomically (temporary file, then rename): a kill leaves no half file."""
        tensors = {
            **{f"force_function_{i}": f.contiguous() for i, f in enumerate(self.force.functions)},
            "force_core": self.force.core.contiguous(),
            **{f"field_{k}": v.contiguous() for k, v in self.field.items()},
        }
        files.save(
            path,
            {
                "format": FORMAT,
                "config": self.config.to_dict(),
                "config_hash": self.config_hash,
                "names": list(self.force.names),
                "grids": {k: list(v) for k, v in self.grids.items()},
                "stats": self.stats,
                "tensors": tensors,
            },
        )

    @classmethod
    def load(cls, path: str | Path) -> Basis:
        remedy = f"rebuild it with `python -m ptwin.pgd out={path}`"
        payload = files.load(path, FORMAT, remedy, error=BasisError)
        config = PGDConfig.from_dict(payload["config"])
        if config.hash() != payload["config_hash"]:
            raise BasisError(f"{path}: stored config does not match its hash; {remedy}")
        tensors, names = payload["tensors"], payload["names"]
        force = SeparatedForce(
            names, [tensors[f"force_function_{i}"] for i in range(len(names))], tensors["force_core"]
        )
        field = {k.removeprefix("field_"): v for k, v in tensors.items() if k.startswith("field_")}
        grids = {k: tuple(v) for k, v in payload["grids"].items()}
        return cls(config, force, grids, field, payload["stats"])
