"""python train.py [overrides]: the ptwin pipeline on the bundled default.

Today it prepares the PGD fluid-force layer the identification chain runs through:
reuses (or builds once) the cached basis for the chosen ``pgd`` preset, verifies it
against the closed form and the exact discrete model, and writes ``summary.json`` in
the run directory. The recording sets and the identification chain come next (see
README, "Status").
"""

from __future__ import annotations

import json
from pathlib import Path

import hydra
import torch
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from ptwin.pgd.basis import Basis
from ptwin.pgd.cache import cached_basis
from ptwin.pgd.config import PGDConfig
from ptwin.pgd.verify import verify
from ptwin.physics.fluid_force import FluidForce
from ptwin.schema import register

register()


def train(cfg: DictConfig, output_dir: Path) -> dict:
    """Run the pipeline for ``cfg`` and leave its results in ``output_dir``."""
    torch.manual_seed(cfg.seed)
    config = PGDConfig.from_dict(OmegaConf.to_container(cfg.pgd, resolve=True))
    path = cached_basis(config, cfg.cache_dir)
    basis = Basis.load(path)
    layer = FluidForce(basis, permeability=cfg.permeability, viscosity=cfg.viscosity).to(cfg.device)
    report = verify(basis)
    summary = {
        "basis": str(path),
        "basis_hash": basis.config_hash,
        "modes_per_mesh": basis.stats["modes_per_mesh"],
        "build_seconds": basis.stats["seconds"],
        "max_error_vs_closed_form": report["closed_form"],
        "max_error_vs_discrete_model": report["discrete"],
        "permeability": layer.permeability.item(),
    }
    output_dir.mkdir(parents=True, exist_ok=True)
    (output_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    print(
        f"PGD basis {path.name}: {sum(summary['modes_per_mesh'])} modes, "
        f"max force error {report['closed_form']:.1e} vs closed form, "
        f"{report['discrete']:.1e} vs its discrete model"
    )
    print(f"results in {output_dir}")
    return summary


@hydra.main(version_base="1.3", config_path="configs", config_name="train")
def main(cfg: DictConfig) -> None:
    train(cfg, Path(HydraConfig.get().runtime.output_dir))


if __name__ == "__main__":
    main()
