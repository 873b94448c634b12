"""The separated basis on disk: modes, grids, config and hash, format version, checksum.

Stored with ``torch.save`` as a plain dict of tensors and built-in types, loaded with
``weights_only=True``. A sha256 over every tensor's bytes catches corruption that the
zip container lets through; any other format version is refused.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

import torch

from ptwin.pgd.compression import SeparatedForce
from ptwin.pgd.config import PGDConfig

FORMAT = "ptwin-pgd-basis/1"


class BasisError(ValueError):
    """A basis file that cannot be used (wrong version, corrupted, mismatched)."""


@dataclass
class Basis:
    """A built PGD basis: the force over the parameters and the pressure field."""

    config: PGDConfig
    force: SeparatedForce
    grids: dict[str, tuple[float, float, int]]
    field: dict[str, torch.Tensor]
    stats: dict

    @property
    def config_hash(self) -> str:
        return self.config.hash()

    @classmethod
    def from_build(cls, config, problem, solution, force, stats) -> Basis:
        grids = {}
        for dim in problem.dims[2:]:
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
        payload = {
            "format": FORMAT,
            "config": self.config.to_dict(),
            "config_hash": self.config_hash,
            "names": list(self.force.names),
            "grids": {k: list(v) for k, v in self.grids.items()},
            "stats": self.stats,
            "tensors": tensors,
            "checksum": _checksum(tensors),
        }
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        temporary = path.with_suffix(path.suffix + ".tmp")
        torch.save(payload, temporary)
        os.replace(temporary, path)

    @classmethod
    def load(cls, path: str | Path) -> Basis:
        path = Path(path)
        if not path.is_file():
            raise BasisError(f"{path}: no PGD basis file there; build one with `python -m ptwin.pgd out={path}`")
        try:
            payload = torch.load(path, weights_only=True)
        except Exception as error:  # the zip reader raises many kinds on a damaged file
            raise BasisError(
                f"{path}: not a readable PGD basis ({error.__class__.__name__}); rebuild it with `python -m ptwin.pgd`"
            ) from None
        if not isinstance(payload, dict) or payload.get("format") != FORMAT:
            found = payload.get("format") if isinstance(payload, dict) else type(payload).__name__
            raise BasisError(
                f"{path}: basis format {found!r}, this ptwin reads {FORMAT!r}; rebuild it with `python -m ptwin.pgd`"
            )
        tensors = payload["tensors"]
        if _checksum(tensors) != payload["checksum"]:
            raise BasisError(f"{path}: checksum mismatch, the file is corrupted; rebuild it with `python -m ptwin.pgd`")
        config = PGDConfig.from_dict(payload["config"])
        if config.hash() != payload["config_hash"]:
            raise BasisError(f"{path}: stored config does not match its hash; rebuild it with `python -m ptwin.pgd`")
        names = payload["names"]
        force = SeparatedForce(
            names, [tensors[f"force_function_{i}"] for i in range(len(names))], tensors["force_core"]
        )
        field = {k.removeprefix("field_"): v for k, v in tensors.items() if k.startswith("field_")}
        grids = {k: tuple(v) for k, v in payload["grids"].items()}
        return cls(config, force, grids, field, payload["stats"])


def _checksum(tensors: dict[str, torch.Tensor]) -> str:
    digest = hashlib.sha256()
    for name in sorted(tensors):
        digest.update(name.encode())
        digest.update(tensors[name].contiguous().view(torch.uint8).numpy().tobytes())
    return digest.hexdigest()
