"""A force map: every spot's diagnosis (``spot.py``) run by the engine, each result written as it comes
(atomically, so a killed map resumes from them), then the table, the summary, the maps and the report."""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields
from functools import partial
from pathlib import Path

import pandas as pd
from tqdm import tqdm

from ptwin.checks import first_line
from ptwin.data.recordings import RecordingError
from ptwin.diagnosis.spatial import summarise_map
from ptwin.pipeline.engine import run_each
from ptwin.pipeline.settings import MapRunSettings, Settings
from ptwin.pipeline.spot import COLUMNS, RESULTS, Spot, blank_row, diagnose_spot, position_of, result_path
from ptwin.reporting.maps import write_map_outputs

# A spot result stored under another format is run again: /2 leaves blank a K whose fit left no fluid force, where
# /1 gave the value the fit stopped at (a map resumed across the change would have mixed the two).
FORMAT = "ptwin-spot/2"


@dataclass
class MapResult:
    table: pd.DataFrame  # spots.csv
    summary: dict  # map_summary.json


def find_spots(folder: Path) -> list[Spot]:
    """The spots of the map in ``folder``: its sub-folders, by name."""
    if not folder.is_dir():
        raise RecordingError(f"{folder}: no such force-map folder; give data.path=<folder of recording-set folders>")
    if (folder / "curves.csv").exists():
        raise RecordingError(
            f"{folder}: a single recording set, not a force map; give data.path=<folder of spot folders> "
            f"(python train.py data.path={folder} diagnoses this set)"
        )
    spots = [Spot(p.name, p, position_of(p)) for p in sorted(folder.iterdir()) if p.is_dir() and p.name[0] != "."]
    if not spots:
        raise RecordingError(f"{folder}: no spot folders; a force map holds one recording-set folder per spot")
    return spots


def run_map(settings: MapRunSettings, output_dir: Path, progress: Callable[[str], None] = print) -> MapResult:
    """Diagnose every spot of the map ``settings.data.path`` (those already in ``output_dir`` from a run
    with the same settings are kept) and write the map's outputs into ``output_dir``."""
    spots = find_spots(Path(settings.data.path))
    results_dir = output_dir / RESULTS
    results_dir.mkdir(parents=True, exist_ok=True)
    spot_settings = _spot_settings(settings)
    fingerprint = _fingerprint(spot_settings, settings.map.hybrid)
    done = {spot.name: row for spot in spots if (row := _stored_row(output_dir / result_path(spot), fingerprint))}
    todo = [spot for spot in spots if spot.name not in done]
    m = settings.map
    engine = "serial" if m.scheduler == "serial" else f"Dask ({m.scheduler})"
    progress(f"{len(spots)} spots, {len(done)} already diagnosed in {results_dir}; {len(todo)} to run on {engine}")
    task = partial(_spot_task, settings=spot_settings, hybrid=m.hybrid, results_dir=results_dir)
    with tqdm(total=len(spots), initial=len(done), unit="spot", desc="spots") as bar:
        for spot, result in run_each(task, todo, m.scheduler, m.workers, _lost):
            _store(output_dir / result_path(spot), {"format": FORMAT, "settings": fingerprint, **result})
            done[spot.name] = result["row"]
            bar.update()
    table = pd.DataFrame([done[spot.name] for spot in spots], columns=list(COLUMNS))
    summary = summarise_map(table)
    write_map_outputs(output_dir, table, summary, settings.figures)
    for sentence in summary["sentences"]:
        progress(sentence)
    progress(f"map results in {output_dir}: spots.csv, map_summary.json, report.md")
    return MapResult(table, summary)


def _spot_settings(settings: MapRunSettings) -> Settings:
    """A spot's settings: those of the map without its ``map`` group."""
    return Settings(**{f.name: getattr(settings, f.name) for f in fields(Settings)})


def _spot_task(spot: Spot, settings: Settings, hybrid: bool, results_dir: Path) -> dict:
    return diagnose_spot(spot, settings, hybrid, results_dir / spot.name)


def _lost(spot: Spot, error: Exception) -> dict:
    """The result of a spot whose task never came back (its worker died): a row that says so."""
    row = blank_row(spot)
    row["status"] = f"its task was lost ({first_line(error)}); rerun the map to retry it"
    return {"row": row, "diagnosis": None, "lost": True}


def _fingerprint(settings: Settings, hybrid: bool) -> str:
    """What a stored spot result was computed with: the spot settings (not the map's path) and the twin."""
    values = asdict(settings)
    values["data"].pop("path")
    values.pop("figures")  # a spot draws none: the map's own PNGs are all it decides
    text = json.dumps({"settings": values, "hybrid": hybrid}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _stored_row(path: Path, fingerprint: str) -> dict | None:
    """The row stored at ``path`` by a run with the same settings; None (to rerun it) otherwise. A spot
    whose task was lost is rerun too."""
    try:
        stored = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if stored.get("format") != FORMAT or stored.get("settings") != fingerprint or stored.get("lost"):
        return None
    return stored["row"]


def _store(path: Path, payload: dict) -> None:
    """Write ``payload`` as JSON atomically: a kill leaves the file whole or absent."""
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(json.dumps(payload, indent=1))
    os.replace(temporary, path)
