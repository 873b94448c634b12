"""Reuse a built basis keyed by its config hash; build it when absent or unusable."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from ptwin.pgd.basis import Basis, BasisError
from ptwin.pgd.build import build_basis
from ptwin.pgd.config import PGDConfig

# Bases this process has loaded, by file and its modification time: a force map's worker loads the
# basis once for all of its spots. Bases are read-only once built.
_LOADED: dict[tuple[Path, int], Basis] = {}


def cache_path(config: PGDConfig, cache_dir: str | Path) -> Path:
    """Where the basis of ``config`` lives in ``cache_dir``."""
    return Path(cache_dir) / f"pgd-{config.coordinates}-{config.hash()[:16]}.pt"


def cached_basis(config: PGDConfig, cache_dir: str | Path, progress: Callable[[str], None] = print) -> Basis:
    """The basis for ``config`` from ``cache_dir``, built on first use; a damaged or outdated
    cached file is rebuilt, with one line saying so."""
    path = cache_path(config, cache_dir)
    if path.is_file():
        key = (path.resolve(), path.stat().st_mtime_ns)
        try:
            basis = _LOADED[key] if key in _LOADED else Basis.load(path)
        except BasisError as error:
            progress(f"cached PGD basis unusable ({error}): rebuilding it")
        else:
            progress(f"reusing PGD basis {path}")
            _LOADED[key] = basis
            return basis
    else:
        progress(f"no cached PGD basis for this config: building {path}")
    basis = build_basis(config, progress)
    basis.save(path)
    return basis
