"""python train.py [overrides]: the ptwin pipeline on the bundled default.

Today it reads and checks the recording set (``data.path``) and summarises its
kinematics per curve, then prepares the PGD fluid-force layer the identification
chain runs through: reuses (or builds once) the cached basis for the chosen ``pgd``
preset and verifies it against the closed form and the exact discrete model. All
numbers go to ``summary.json`` in the run directory. The identification chain comes
next (see README, "Status"). Bad input ends the run with one line and exit code 2.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import hydra
import torch
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from ptwin.data.recordings import RecordingError, load_recordings
from ptwin.pgd.basis import Basis
from ptwin.pgd.cache import cached_basis
from ptwin.pgd.config import PGDConfig
from ptwin.pgd.verify import verify
from ptwin.physics.fluid_force import FluidForce
from ptwin.physics.kinematics import curve_kinematics
from ptwin.schema import register

register()


def train(cfg: DictConfig, output_dir: Path) -> dict:
    """Run the pipeline for ``cfg`` and leave its results in ``output_dir``."""
    torch.manual_seed(cfg.seed)
    recordings = load_recordings(cfg.data.path)
    curves = curve_kinematics(recordings, smoothing=cfg.data.smoothing)
    print(
        f"{'curve':>6s} {'speed µm/s':>10s} {'contact':>10s} {'max depth µm':>12s} {'noise nN':>8s} {'offset nN':>9s}"
    )
    for c in curves:
        print(
            f"{c.curve:>6s} {c.base_speed * 1e6:10.3g} {int(c.in_contact.sum()):10d} {c.depth.max() * 1e6:12.3f} "
            f"{c.noise_floor * 1e9:8.3f} {c.baseline_offset * 1e9:9.3f}"
        )
    config = PGDConfig.from_dict(OmegaConf.to_container(cfg.pgd, resolve=True))
    path = cached_basis(config, cfg.cache_dir)
    basis = Basis.load(path)
    layer = FluidForce(basis, permeability=cfg.permeability, viscosity=cfg.viscosity).to(cfg.device)
    report = verify(basis)
    summary = {
        "recordings": str(recordings.path),
        "curves": {
            c.curve: {"base_speed": c.base_speed, "noise_floor": c.noise_floor, "baseline_offset": c.baseline_offset}
            for c in curves
        },
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
    try:
        train(cfg, Path(HydraConfig.get().runtime.output_dir))
    except RecordingError as error:
        print(error, file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
