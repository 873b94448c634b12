"""python -m ptwin.basis pgd=<default|precise|paper> [pgd.coordinates=paper] [out=<file>]

Builds a basis, saves it (by default into the cache, where train.py looks for it),
prints modes, time, peak memory and its errors against the closed form and against a
direct solve of the same discrete problem. A face beside train.py: it uses the PGD solver
below physics and the fluid layer's check in physics, so it sits above both."""

from __future__ import annotations

from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from ptwin.app import exit_now, one_line_errors, run_face, start, typed
from ptwin.pgd.build import build_basis
from ptwin.pgd.cache import cache_path
from ptwin.physics.fluid_accuracy import verify

start()


@hydra.main(version_base="1.3", config_path="../configs", config_name="pgd_build")
def main(cfg: DictConfig) -> None:
    with one_line_errors(Path(HydraConfig.get().runtime.output_dir)):
        settings = typed(cfg)
        config = settings.pgd
        out = settings.out or cache_path(config, settings.cache_dir)
        basis = build_basis(config)
        basis.save(out)
        stats = basis.stats
        print(
            f"saved {out}: {stats['modes_per_mesh']} modes, {stats['seconds']:.1f} s, "
            f"peak memory {stats['peak_rss_bytes'] / 2**30:.2f} GiB, force ranks {stats['force_ranks']}"
        )
        report = verify(basis)
        print(f"max relative force error vs closed form ({report['points']} points): {report['closed_form']:.2e}")
        print(f"max relative force error vs direct solve of the same discrete problem: {report['discrete']:.2e}")


if __name__ == "__main__":
    run_face(main)
    exit_now()
