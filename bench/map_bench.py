"""make bench (part): a generated 16×16 force map (3 speeds × 1000 samples per spot, K and E* varying over
it, pore-pressure relaxation concealed in a central disc) through ``python -m ptwin.map``'s pipeline.

Prints the wall time of the whole map on a Dask LocalCluster (one worker per core; goal ≤ 70 s on 2
cores), the per-spot time, the same spots' time serially (on a sample of them: a full serial map takes
a core for as long as the whole map's work), K's error per spot against the truth and the share of
spots whose verdict on the concealed term matches the disc. The map is generated once into the cache
(minutes) and reused.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
from hydra import compose, initialize_config_dir

from ptwin.app import register, typed
from ptwin.pipeline.forcemap import MapResult, run_map
from ptwin.synth.cli import main as synth

ROOT = Path(__file__).resolve().parents[1]
SIDE, SPEEDS, SAMPLES, TERM = 16, ("2e-6", "8e-6", "40e-6"), "1000", "pore_pressure_relaxation"
SERIAL_SAMPLE = 16  # spots timed serially


def generated_map(cache: Path) -> tuple[Path, pd.DataFrame]:
    folder = cache / f"bench-map-{SIDE}x{SIDE}-{SAMPLES}"
    truth = folder.with_suffix(".truth.csv")
    if not truth.is_file():
        print(f"generating the {SIDE}×{SIDE} map into {folder} (once; minutes)", flush=True)
        shutil.rmtree(folder, ignore_errors=True)
        synth(
            ["--map", str(SIDE), str(SIDE), "--out", str(folder), "--truth", str(truth), "--speeds", *SPEEDS]
            + ["--samples", SAMPLES, "--region-effect", f"{TERM}:M=3e4", "--seed", "11"]
        )
    return folder, pd.read_csv(truth)


def settings(folder: Path, cache: Path, *overrides):
    register()
    with initialize_config_dir(config_dir=str(ROOT / "configs"), version_base="1.3"):
        return typed(compose("map", [f"data.path={folder}", f"cache_dir={cache}", *overrides]))


def timed_map(folder: Path, cache: Path, *overrides: str, spots: int | None = None) -> tuple[MapResult, float]:
    """The map in ``folder`` (or ``spots`` of its spots, drawn at random over it: every n-th spot in name order
    is one column of the grid, the disc's spots and the slow ones left out) run with ``overrides`` into a
    scratch folder, and the wall time it took [s]."""
    with tempfile.TemporaryDirectory() as sample, tempfile.TemporaryDirectory() as out:
        if spots is not None:
            names = sorted(spot.name for spot in folder.iterdir() if spot.is_dir())
            for name in np.random.default_rng(0).choice(names, spots, replace=False):
                os.symlink(folder / name, Path(sample) / name)
            folder = Path(sample)
        started = time.perf_counter()
        result = run_map(settings(folder, cache, *overrides), Path(out), progress=lambda line: None)
        return result, time.perf_counter() - started


def main() -> None:
    warnings.filterwarnings("ignore", category=RuntimeWarning)
    cache = Path(os.environ.get("PTWIN_CACHE", ROOT / ".cache" / "ptwin"))
    folder, truth = generated_map(cache)
    cores = os.cpu_count()
    result, wall = timed_map(folder, cache, "map.scheduler=local")
    table = result.table.merge(truth, on="spot", suffixes=("", "_true"))
    serial, serial_wall = timed_map(folder, cache, "map.scheduler=serial", spots=SERIAL_SAMPLE)
    ok = table[table["status"] == "ok"]
    error = (ok["permeability"] / ok["permeability_true"] - 1).abs()
    named = ok["left_out"].fillna("").str.contains(TERM) & ok["confidence"].fillna("").str.contains("strong|moderate")
    print(f"force map {SIDE}×{SIDE} ({len(truth)} spots, {len(SPEEDS)} speeds × {SAMPLES} samples), {cores} cores")
    print(
        f"  Dask LocalCluster ({cores} workers): {wall:.0f} s wall (goal ≤ 70 s on 2 cores), "
        f"{wall * cores / len(truth):.2f} core-seconds per spot (goal ≤ 0.5)"
    )
    seconds = result.table["seconds"]
    slow = seconds >= 5 * seconds.median()
    print(
        f"    per-spot diagnosis time on a worker: median {seconds.median():.2f} s, mean {seconds.mean():.2f} s; "
        f"{slow.sum()} spots of ≥ 5× the median take {100 * seconds[slow].sum() / seconds.sum():.0f}% of the time"
    )
    # The sample's own spots on the workers, not the map's mean: a sample of 16 may miss the slow spots.
    on_workers = result.table.set_index("spot").loc[serial.table["spot"], "seconds"].sum()
    print(
        f"  serial, {len(serial.table)} of its spots: {serial_wall:.0f} s wall, {serial_wall / len(serial.table):.2f} "
        f"s per spot, against {on_workers / len(serial.table):.2f} s for the same spots on a worker; the map's "
        f"diagnoses sum to {seconds.sum():.0f} core-seconds"
    )
    median, largest = 100 * error.median(), 100 * error.max()
    print(f"  diagnosed {len(ok)}/{len(truth)}; K error per spot: median {median:.2f}%, max {largest:.2f}%")
    agree = 100 * (named == ok["in_region"]).mean()
    print(f"  {TERM} named (moderate/strong) exactly inside the disc at {agree:.1f}% of spots")
    for sentence in result.summary["sentences"]:
        print(f"  {sentence}")


if __name__ == "__main__":
    main()
