"""Reuse a built basis keyed by its config hash; build it only when absent."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from ptwin.pgd.build import build_basis
from ptwin.pgd.config import PGDConfig


def cached_basis(config: PGDConfig, cache_dir: str | Path, progress: Callable[[str], None] = print) -> Path:
    """Path of the basis for ``config`` in ``cache_dir``, building it on first use."""
    path = Path(cache_dir) / f"pgd-{config.coordinates}-{config.hash()[:16]}.pt"
    if path.is_file():
        progress(f"reusing PGD basis {path}")
        return path
    progress(f"no cached PGD basis for this config: building {path}")
    build_basis(config, progress).save(path)
    return path
