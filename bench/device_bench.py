"""make bench (part), where a CUDA device is present: the hybrid stage and the 16×16 map on that machine.

Prints, for the demo set, the identification and the hybrid stage (every λ of ``optim.hybrid``, as
``train.py`` trains them) with ``device=cpu`` and with ``device=cuda``, each after one untimed run, and the K
and validation RMSE each reached (they must agree: the device changes no number beyond rounding). Then
``map_bench``'s 16×16 map on a Dask LocalCluster over every core of the machine (spots on the CPU), and a
sample of its spots serially on each device, with whether their verdicts agree. Last, the whole demo
(``python train.py``) on each device, and how far apart any two numbers of their diagnosis.json lie. Nothing in
ptwin requires a GPU; without one this prints one line and stops.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import torch
from hydra import compose, initialize_config_dir

from bench.map_bench import generated_map, timed_map
from ptwin.app import register, typed
from ptwin.fitting.hybrid_training import train_hybrid
from ptwin.pipeline.identify import identify
from ptwin.pipeline.prepare import prepare

ROOT = Path(__file__).resolve().parents[1]
SERIAL_SPOTS = 8  # spots of the map diagnosed serially, on the CPU and on the GPU


def _synchronised() -> float:
    if torch.cuda.is_available():
        torch.cuda.synchronize()
    return time.perf_counter()


def hybrid_stage(device: str, cache: Path, report: bool = True) -> None:
    register()
    with initialize_config_dir(config_dir=str(ROOT / "configs"), version_base="1.3"):
        overrides = [f"data.path={ROOT / 'data' / 'demo'}", f"cache_dir={cache}", f"device={device}"]
        settings = typed(compose(config_name="train", overrides=overrides))
    torch.manual_seed(settings.seed)
    prepared = prepare(settings, progress=lambda line: None)
    samples, split = prepared.samples, prepared.split
    started = _synchronised()
    base = identify(prepared, settings.optim, progress=lambda line: None).base
    identified = _synchronised()
    outcome = train_hybrid(
        lambda: prepared.make_model.twin(base.permeability, prepared.noise_floor, samples, split.train),
        samples,
        split.train,
        split.val,
        settings.optim.hybrid,
    )
    trained = _synchronised()
    if not report:
        return
    print(
        f"  {device:4}: identify {identified - started:5.1f} s, hybrid stage {trained - identified:5.1f} s "
        f"({sum(outcome.iterations)} LM iterations over {len(outcome.iterations)} λ); base K "
        f"{base.permeability:.6e} m², twin K {outcome.twin.physics.fluid.permeability.item():.6e} m², "
        f"validation RMSE {min(outcome.val_rmse):.6e} N",
        flush=True,
    )


def whole_demo(cache: Path) -> None:
    numbers = {}
    with tempfile.TemporaryDirectory() as out:
        for device in ("cpu", "cuda"):
            started = time.perf_counter()
            overrides = [f"device={device}", f"cache_dir={cache}", f"hydra.run.dir={out}/{device}"]
            done = subprocess.run([sys.executable, "train.py", *overrides], cwd=ROOT, capture_output=True, text=True)
            seconds = time.perf_counter() - started
            if done.returncode:
                print(f"  python train.py device={device} failed: {done.stderr.strip().splitlines()[-1:]}")
                return
            numbers[device] = _numbers(json.loads(Path(out, device, "diagnosis.json").read_text()))
            print(f"  python train.py device={device}: {seconds:.1f} s wall", flush=True)
    cpu, cuda = numbers["cpu"], numbers["cuda"]
    spread = max(abs(a - b) / max(abs(a), abs(b), 1e-300) for a, b in zip(cpu, cuda))
    same = "the same" if len(cpu) == len(cuda) else "NOT the same"
    print(f"  their diagnosis.json: {same} {len(cpu)} numbers, the furthest apart by {spread:.1e} (relative)")


def _numbers(tree) -> list[float]:
    """Every number in a JSON tree, in document order."""
    if isinstance(tree, dict):
        return [n for value in tree.values() for n in _numbers(value)]
    if isinstance(tree, list):
        return [n for value in tree for n in _numbers(value)]
    return [float(tree)] if isinstance(tree, int | float) and not isinstance(tree, bool) else []


def local_map(cache: Path) -> None:
    folder, truth = generated_map(cache)
    cores = os.cpu_count()
    result, wall = timed_map(folder, cache, "map.scheduler=local")
    print(
        f"  Dask LocalCluster, {cores} workers, spots on the CPU: {wall:.0f} s wall, "
        f"{wall * cores / len(truth):.2f} core-seconds per spot; {_outcome(result.table)}",
        flush=True,
    )


def serial_spots(cache: Path) -> None:
    folder = generated_map(cache)[0]
    tables = {}
    for device in ("cpu", "cuda"):
        serial, wall = timed_map(folder, cache, "map.scheduler=serial", f"device={device}", spots=SERIAL_SPOTS)
        tables[device] = serial.table.set_index("spot")
        print(
            f"  serially, device={device}, {SERIAL_SPOTS} of its spots: {wall / SERIAL_SPOTS:.2f} s per spot; "
            f"{_outcome(serial.table)}",
            flush=True,
        )
    cpu, cuda = tables["cpu"], tables["cuda"]
    same = cpu[["status", "left_out", "confidence"]].fillna("") == cuda[["status", "left_out", "confidence"]].fillna("")
    spread = (cuda["permeability"] / cpu["permeability"] - 1).abs().max()
    print(
        f"  the same verdict on both devices at {same.all(axis=1).sum()}/{len(cpu)} spots; K differs by ≤ {spread:.1e}"
    )


def _outcome(table) -> str:
    """The median time a spot took where it ran, and how many spots were diagnosed (the first other status)."""
    ok = table["status"] == "ok"
    first = "" if ok.all() else f" (first other: {table.loc[~ok, 'status'].iloc[0]})"
    return f"median {table['seconds'].median():.2f} s a spot on its worker, {ok.sum()}/{len(table)} diagnosed{first}"


def main() -> None:
    if not torch.cuda.is_available():
        print("device bench: no CUDA device here; nothing to time (ptwin runs on the CPU)")
        return
    warnings.filterwarnings("ignore", category=RuntimeWarning)
    cache = Path(os.environ.get("PTWIN_CACHE", ROOT / ".cache" / "ptwin"))
    print(f"{torch.cuda.get_device_name()}, {os.cpu_count()} CPU cores, torch {torch.__version__}")
    print("demo set, identification and hybrid stage:", flush=True)
    for device in ("cpu", "cuda"):
        hybrid_stage(device, cache, report=False)  # the first run's one-time costs (basis, CUDA context) apart
        hybrid_stage(device, cache)
    print(f"force map of map_bench ({len(generated_map(cache)[1])} spots):", flush=True)
    local_map(cache)
    serial_spots(cache)
    print("demo set, the whole run:", flush=True)
    whole_demo(cache)


if __name__ == "__main__":
    main()
