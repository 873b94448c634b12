"""make bench: PGD build time and memory per preset (scaled and paper coordinates
side by side), accuracy, and online throughput of the fluid-force layer."""

from __future__ import annotations

import argparse
import time

import torch
import yaml

from ptwin.pgd.build import build_basis
from ptwin.pgd.config import PGDConfig
from ptwin.pgd.problem import build_problem
from ptwin.pgd.reference import discrete_force_coefficient
from ptwin.physics.fluid_accuracy import verify
from ptwin.physics.fluid_force import FluidForce


def preset(name: str) -> dict:
    values = yaml.safe_load(open(f"configs/pgd/{name}.yaml"))
    parents = [d for d in values.pop("defaults", []) if d not in ("schema", "_self_")]
    merged = {}
    for parent in parents:
        merged.update(preset(parent))
    for key, value in values.items():
        merged[key] = {**merged.get(key, {}), **value} if isinstance(value, dict) else value
    return merged


def throughput(layer: FluidForce, batch: int = 1_000_000, repeats: int = 5):
    generator = torch.Generator().manual_seed(0)
    velocity = 10 ** (torch.rand(batch, generator=generator, dtype=torch.float64) * 3 - 7)
    radius = 10 ** (torch.rand(batch, generator=generator, dtype=torch.float64) * 2 - 7) + 1e-7
    height = torch.full_like(radius, 6e-3)
    layer(velocity, radius, height)
    start = time.perf_counter()
    with torch.no_grad():
        for _ in range(repeats):
            layer(velocity, radius, height)
    forward = batch * repeats / (time.perf_counter() - start)
    radius.requires_grad_(True)
    start = time.perf_counter()
    for _ in range(repeats):
        layer.zero_grad()
        layer(velocity, radius, height).sum().backward()
    backward = batch * repeats / (time.perf_counter() - start)
    return forward, backward


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--presets", nargs="+", default=["default", "paper", "precise"])
    args = parser.parse_args()
    print(
        f"{'preset':10s} {'coords':7s} {'modes':>10s} {'build s':>8s} {'peak GiB':>8s} "
        f"{'vs closed':>10s} {'vs discrete':>11s} {'fwd /s':>9s} {'fwd+bwd /s':>10s} {'speed-up':>9s}"
    )
    for name in args.presets:
        for coordinates in ("scaled", "paper"):
            values = preset(name)
            values["coordinates"] = coordinates
            config = PGDConfig.from_dict(values)
            basis = build_basis(config, progress=lambda line: None)
            report = verify(basis)
            layer = FluidForce(basis, permeability=2e-16, viscosity=1e-3)
            forward, backward = throughput(layer)
            problem = build_problem(config)
            start = time.perf_counter()
            discrete_force_coefficient(problem, [1.0e3])
            direct = time.perf_counter() - start
            stats = basis.stats
            if (name, coordinates) == ("default", "scaled"):
                where = "its two meshes side by side" if stats["meshes_side_by_side"] else "one mesh after the other"
                goal = (
                    f"pgd=default (what train.py uses) built in {stats['seconds']:.1f} s (goal ≤ 3 s), {where}, "
                    f"{stats['core_seconds']:.1f} core-seconds"
                )
            print(
                f"{name:10s} {coordinates:7s} {str(stats['modes_per_mesh']):>10s} {stats['seconds']:8.1f} "
                f"{stats['peak_rss_bytes'] / 2**30:8.2f} {report['closed_form']:10.1e} {report['discrete']:11.1e} "
                f"{forward:9.2e} {backward:10.2e} {forward * direct:9.1e}",
                flush=True,
            )
    if "default" in args.presets:
        print(goal)


if __name__ == "__main__":
    main()
