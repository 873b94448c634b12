"""One spot of a force map: the chain of ``train.py`` on its recording set (prepare → identify →
diagnose, the hybrid twin only on request), reduced to one row of ``spots.csv``.

A spot that cannot be diagnosed is a row too: its ``status`` is the one line that says why.
"""

from __future__ import annotations

import time
import traceback
from dataclasses import dataclass, replace
from pathlib import Path

import torch
import yaml

from ptwin.checks import first_line
from ptwin.data.recordings import RecordingError
from ptwin.diagnosis.diagnose import Diagnosis
from ptwin.diagnosis.words import finite_or_none
from ptwin.files import StoredFileError
from ptwin.fitting.lm import FitError
from ptwin.pipeline.identify import identify
from ptwin.pipeline.prepare import prepare
from ptwin.pipeline.run import diagnose_set
from ptwin.pipeline.settings import Settings
from ptwin.pipeline.twin import train_twin

OK = "ok"
RESULTS = "spots"  # the folder of a map's output where each spot's result lands
COLUMNS = (
    "spot",
    "x",
    "y",
    "status",
    "permeability",
    "permeability_low",
    "permeability_high",
    "effective_modulus",
    "left_out",
    "confidence",
    "confounded",
    "unexplained",
    "base_rmse_over_noise",
    "corrected_rmse_over_noise",
    "seconds",
)


@dataclass(frozen=True)
class Spot:
    """A spot of a map: its name (the folder's), its recording set and its place (x, y) [m], if given."""

    name: str
    path: Path
    position: tuple[float, float] | None


def position_of(folder: Path) -> tuple[float, float] | None:
    """``position`` from ``folder/meta.yaml`` when it reads as two numbers; else None (a spot whose meta.yaml
    is broken still gets a row: its error is the loader's to report, with the fix)."""
    try:
        x, y = (float(c) for c in yaml.safe_load((folder / "meta.yaml").read_text())["position"])
    except Exception:  # any unreadable meta.yaml: the loader says why when the spot runs
        return None
    return x, y


def result_path(spot: Spot) -> Path:
    """Where a spot's result lands, relative to the map's output folder."""
    return Path(RESULTS) / f"{spot.name}.json"


def blank_row(spot: Spot) -> dict:
    """The row of a spot before (or without) its diagnosis: its name and place, nothing named."""
    row = {column: None for column in COLUMNS}
    x, y = spot.position or (None, None)
    row.update(spot=spot.name, x=x, y=y, left_out="", confidence="", confounded="", unexplained=False)
    return row


def diagnose_spot(spot: Spot, settings: Settings, hybrid: bool, output_dir: Path) -> dict:
    """{"row": the spot's row of ``spots.csv``, "diagnosis": its diagnosis.json or None, and "traceback" of
    anything unforeseen}; never raises for what is wrong with the spot: the row's status says it.
    ``output_dir``: the spot's own folder (the hybrid twin's checkpoints)."""
    started = time.perf_counter()
    torch.manual_seed(settings.seed)  # each spot alike, whichever worker and order runs it
    row = blank_row(spot)
    result = {"row": row, "diagnosis": None}
    try:
        diagnosis = _diagnosis(replace(settings, data=replace(settings.data, path=str(spot.path))), hybrid, output_dir)
    except (RecordingError, StoredFileError, FitError) as error:
        row["status"] = first_line(error)
    except Exception as error:  # a spot never stops the map: the line names it, the traceback comes back with it
        first = first_line(error, silent="")
        row["status"] = f"unexpected {type(error).__name__} ({first}); see {result_path(spot)}: please report it"
        result["traceback"] = traceback.format_exc()
    else:
        row.update(_row(diagnosis), status=OK)
        result["diagnosis"] = diagnosis.to_json()
    row["seconds"] = time.perf_counter() - started
    return finite_or_none(result)


def _diagnosis(settings: Settings, hybrid: bool, output_dir: Path) -> Diagnosis:
    def quiet(_: str) -> None:
        pass

    prepared = prepare(settings, quiet)
    identification = identify(prepared, settings.optim, quiet, chain=False)
    if not hybrid:
        return diagnose_set(prepared, identification, None, settings, quiet)
    twin = train_twin(prepared, identification.base.permeability, prepared.noise_floor, settings, output_dir).twin
    return diagnose_set(prepared, identification, lambda: twin, settings, quiet)


def _row(d: Diagnosis) -> dict:
    """The columns a diagnosis fills: K as diagnosis.json gives it (none where no fluid force was left) and its
    95% interval [m²], E* [Pa], what was named and how surely,
    and the validation RMS of the base and corrected models in units of the noise std."""
    permeability = d.measured_permeability
    low, high = permeability["corrected_interval"]
    return {
        "permeability": permeability["corrected"],
        "permeability_low": low,
        "permeability_high": high,
        "effective_modulus": d.corrected.fit.model.hertz_modulus(),
        "left_out": ";".join(entry["term"] for entry in d.left_out),
        "confidence": ";".join(entry["confidence"] for entry in d.left_out),
        "confounded": ";".join(" vs ".join(group["terms"]) for group in d.confounded),
        "unexplained": d.unexplained,
        "base_rmse_over_noise": d.fit["base"]["val_rmse"] / d.noise_floor,
        "corrected_rmse_over_noise": d.fit["corrected"]["val_rmse"] / d.noise_floor,
    }
