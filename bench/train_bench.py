"""make bench (part): warm `python train.py` on the demo, single 5-curve diagnoses, and LM against Adam on
the hybrid cost.

Prints the wall time of the whole default run with the PGD basis cached, the median of ``DEMO_RUNS`` runs
beside each run's (goal ≤ 6 s on 2 cores: one run's swings by half a second on these machines), the
median time of the whole chain on five sets of discover-bench's original suite (five speeds, a term or
none concealed; goal ≤ 6 s), then trains the default hybrid twin (λ = 1e-2) by LM and by Adam from the
same start and prints the iterations each needs to come within 1% of LM's final cost.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch
from hydra import compose, initialize_config_dir

from ptwin.app import register, typed
from ptwin.fitting.hybrid import hybrid_residual, newton_permeability
from ptwin.fitting.lm import LevenbergMarquardt
from ptwin.pipeline.identify import identify
from ptwin.pipeline.prepare import prepare

ROOT = Path(__file__).resolve().parents[1]
DEMO_RUNS = 5


def warm_run_seconds() -> float:
    subprocess.run([sys.executable, "-m", "ptwin.basis", "--help"], cwd=ROOT, capture_output=True)  # warm imports
    with tempfile.TemporaryDirectory() as out:
        started = time.perf_counter()
        subprocess.run([sys.executable, "train.py", f"hydra.run.dir={out}"], cwd=ROOT, check=True, capture_output=True)
        return time.perf_counter() - started


def lm_against_adam(regularisation: float = 1e-2, adam_steps: int = 5000) -> None:
    cache = os.environ.get("PTWIN_CACHE", str(ROOT / ".cache" / "ptwin"))
    register()
    with initialize_config_dir(config_dir=str(ROOT / "configs"), version_base="1.3"):
        cfg = compose(config_name="train", overrides=[f"data.path={ROOT / 'data' / 'demo'}", f"cache_dir={cache}"])
    settings = typed(cfg)
    prepared = prepare(settings, progress=lambda line: None)
    samples, train = prepared.samples, prepared.split.train
    base = identify(prepared, settings.optim, progress=lambda line: None).base
    noise = samples.noise_floor[train].mean().item()

    def fresh():
        twin = prepared.make_model.twin(base.permeability, noise, samples, train)
        newton_permeability(twin, samples, train, regularisation)
        twin.start_network(samples, train, regularisation)  # where the twin's own runs start (``train_hybrid``)
        groups = twin.parameter_groups()
        return hybrid_residual(twin, samples, train, regularisation, groups["physics"] + groups["network"])

    vector, residual = fresh()
    solver = LevenbergMarquardt(residual, vector.get(), trace=residual.trace)
    costs = []
    started = time.perf_counter()
    solver.run(200, tolerance=1e-12, callback=lambda step: costs.append(step.cost))
    lm_seconds = time.perf_counter() - started
    target = 1.01 * costs[-1]
    lm_iterations = next(i + 1 for i, c in enumerate(costs) if c <= target)

    vector, residual = fresh()
    theta = vector.get().requires_grad_(True)
    optimiser = torch.optim.Adam([theta], lr=1e-2)
    adam_iterations, started = None, time.perf_counter()
    for step in range(1, adam_steps + 1):
        optimiser.zero_grad()
        cost = 0.5 * residual(theta).square().sum()
        if cost.item() <= target:
            adam_iterations = step
            break
        cost.backward()
        optimiser.step()
    adam_seconds = time.perf_counter() - started
    reached = f"{adam_iterations}" if adam_iterations else f"not within {adam_steps} (cost {cost.item():.4g})"
    print(f"hybrid cost to within 1% of LM's final {costs[-1]:.4g} (λ = {regularisation:g}, 26 parameters):")
    print(f"  Levenberg–Marquardt: {lm_iterations} iterations ({lm_seconds:.1f} s for {len(costs)})")
    print(f"  Adam (lr 1e-2):      {reached} iterations ({adam_seconds:.1f} s)")


def single_diagnoses(names=("null", "viscosity small", "relaxation small", "pore large", "strain perm. large")):
    """Seconds of the whole chain on each of discover-bench's original cases ``names`` (a 5-curve set)."""
    from bench.discover_bench import ORIGINAL, diagnose
    from ptwin.synth.simulator import Experiment

    cache = os.environ.get("PTWIN_CACHE", str(ROOT / ".cache" / "ptwin"))
    seconds = []
    with tempfile.TemporaryDirectory() as scratch:
        for case in (c for c in ORIGINAL if c.name in names):
            experiment = Experiment(samples=1000, effects=case.effects, **case.setting)
            seconds.append(diagnose(experiment, Path(scratch) / str(len(seconds)), [f"cache_dir={cache}"])[1])
    return seconds


if __name__ == "__main__":
    demo = [warm_run_seconds() for _ in range(DEMO_RUNS)]
    runs = ", ".join(f"{t:.1f}" for t in demo)
    median = statistics.median(demo)
    print(f"warm `python train.py` on the demo: median {median:.1f} s wall ({runs}; goal ≤ 6 s)", flush=True)
    register()
    times = single_diagnoses()
    listing = ", ".join(f"{t:.1f}" for t in times)
    print(f"single 5-curve diagnosis, the whole chain: median {statistics.median(times):.1f} s ({listing}; goal ≤ 6 s)")
    lm_against_adam()
