"""Real cantilever noise in simulated sets: the pre-contact noise of public JPK curves in place of the simulator's.

The records are those ``../shared/real-noise.md`` measured, read the way it read them: the approach of each public
JPK text export under ``$PTWIN_OPEN_DATA`` (the ``open_data`` folder of github.com/Jhko725/NeuralConstitutiveEq.jl:
PAAm and agarose gels, HeLa cells; Abuhattum et al., iScience 2022) imported by ``python -m ptwin.data.import_afm``,
from 1 µm of travel to 0.3 µm before its contact, a line in z removed. A simulated set drawn without noise gets,
curve by curve, a window of a record of one material (a lab records one sample), scaled by the setting's noise
std over the records' (13 pN): what the bench-sets' p03–p06 did, with other windows, other curves and other
settings. The simulator's model of noise (white plus AR(1)) is ptwin's own; these records are not: PAAm's are close
to white, agarose's and cells' carry slow drift whose block variance grows with the window (real-noise.md).
"""

from __future__ import annotations

import contextlib
import io
import os
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from ptwin.data.import_afm import main as import_afm
from ptwin.synth.simulator import Experiment, simulate

OPEN_DATA = Path(os.environ.get("PTWIN_OPEN_DATA", "-"))
MATERIALS = {"PAAm": "PAAM hydrogel", "agarose": "Agarose", "cells": "Interphase rep 2"}
RECORDED_STD = 1.3e-11  # [N] the records' std (real-noise.md: 9–19 pN, PAAm 12.4–13.5)
SETTLED_TRAVEL, BEFORE_CONTACT = 1.0e-6, 0.3e-6  # [m] real-noise.md's stretch of each approach


def noise_records() -> dict[str, list[np.ndarray]] | None:
    """Each material's pre-contact noise records [N], or None (said in one line) where the public curves are absent."""
    if not all((OPEN_DATA / folder).is_dir() for folder in MATERIALS.values()):
        print("sets with real noise skipped: set PTWIN_OPEN_DATA to open_data/ of Jhko725/NeuralConstitutiveEq.jl")
        return None
    records = {}
    with tempfile.TemporaryDirectory() as scratch:
        for material, folder in MATERIALS.items():
            records[material] = []
            for number, path in enumerate(sorted((OPEN_DATA / folder).rglob("*.tab"))):
                out = Path(scratch) / f"{material}{number}"
                options = ["--probe-radius", "5e-6", "--viscosity", "1e-3", "--thickness", "1e-4"]
                with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                    import_afm([str(path), "--out", str(out), *options])
                records[material] += approach_noise(pd.read_csv(out / "curves.csv"))
    return records


def approach_noise(curves: pd.DataFrame) -> list[np.ndarray]:
    """Each curve's approach from ``SETTLED_TRAVEL`` of travel to ``BEFORE_CONTACT`` before contact, its line in z
    removed [N]."""
    records = []
    for _, curve in curves.groupby("curve", sort=False):
        z, force = curve["z"].to_numpy(), curve["force"].to_numpy()
        stretch = (z > z.min() + SETTLED_TRAVEL) & (z < -BEFORE_CONTACT)
        if "segment" in curve:
            stretch &= (curve["segment"] == "approach").to_numpy()
        z, force = z[stretch], force[stretch]
        records.append(force - np.polyval(np.polyfit(z, force, 1), z))
    return records


def with_real_noise(experiment: Experiment, records: list[np.ndarray]) -> tuple:
    """(meta, curves) of ``experiment`` simulated without noise, each curve given a window of one of ``records``
    (drawn by the experiment's seed: a record with room for it, then a start there) scaled by its noise std over
    ``RECORDED_STD``. No two curves share a sample of a record: real curves are recorded one after another, and
    two windows of the same stretch would give two curves one noise (drawn independently, two of p06's four windows
    overlapped at 41 of 60 seeds on the cells' records and at 44 of 60 on agarose's)."""
    rng = np.random.default_rng([experiment.seed, 7])
    meta, curves = simulate(replace(experiment, noise_std=0.0))
    taken = [np.zeros(record.size, dtype=bool) for record in records]  # the samples given to a curve already
    for curve in curves["curve"].unique():
        rows = (curves["curve"] == curve).to_numpy()
        count = int(rows.sum())
        starts = [_free_starts(used, count) for used in taken]
        room = [i for i, free in enumerate(starts) if free.size]
        if not room:
            raise ValueError(
                f"no noise record has {count} samples left for curve {curve} beside the other curves' windows: "
                "fewer samples a curve"
            )
        chosen = room[rng.integers(len(room))]
        start = int(starts[chosen][rng.integers(starts[chosen].size)])
        taken[chosen][start : start + count] = True
        curves.loc[rows, "force"] += records[chosen][start : start + count] * (experiment.noise_std / RECORDED_STD)
    return meta, curves


def _free_starts(used: np.ndarray, count: int) -> np.ndarray:
    """The starts of the windows of ``count`` samples that hold no ``used`` sample."""
    if used.size < count:
        return np.empty(0, dtype=np.int64)
    return np.flatnonzero(np.convolve(used, np.ones(count, dtype=int), mode="valid") == 0)
