"""python -m ptwin.data.import_afm FILES... --out DIR --probe-radius R --viscosity MU --thickness H0 [--map]

Vendor force-distance files (JPK .jpk-force, Asylum .ibw, NT-MDT text and whatever
afmformats reads) into one recording set, one curve per file. With ``--map``, force-map
files (e.g. JPK .jpk-force-map, one per speed) into a force map: a recording set per spot,
spots matched across the files by their grid index, each with its position. What no file knows
(probe radius, fluid viscosity, sample thickness, and for some formats the spring
constant, sensitivity or speed) comes from the command line. Only the approach is
kept: segment 0, cut at the deepest base position (some files, e.g. Asylum .ibw,
store approach and retract as one segment). The force is kept raw (its baseline
offset is evidence).

z is the base travel from the contact estimated by ``ptwin.data.contact`` (z < 0
before it); meta.yaml says ``contact_point: estimate``, so every run estimates each
curve's contact and baseline again and refines it in the fit. Time: the file's own,
else uniform over travel / approach speed.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import afmformats
import numpy as np
import pandas as pd

from ptwin.data.contact import NoBaseline, estimate_baseline
from ptwin.data.recordings import Meta, RecordingError, load_recordings, write_recordings


def load_datasets(path: Path, overrides: dict) -> list:
    """Every force-distance dataset afmformats reads from ``path`` (one for a curve file, one per spot and
    curve for a force map)."""
    quiet = logging.getLogger("afmformats")
    level, quiet.level = quiet.level, logging.CRITICAL  # it logs a traceback for every error it then raises
    try:
        return afmformats.load_data(path, meta_override=overrides)
    except afmformats.errors.MissingMetaDataError as error:  # a BaseException, not an Exception
        options = " and ".join(f"--{key.replace(' ', '-')}" for key in error.meta_keys)
        raise RecordingError(f"{path}: the file gives no {' or '.join(error.meta_keys)}; pass {options}") from None
    except Exception as error:  # afmformats raises format-specific errors
        raise RecordingError(f"{path}: afmformats cannot read it ({error}); check the file and its format") from None
    finally:
        quiet.setLevel(level)


def approach_curve(path: Path, speed: float | None, overrides: dict) -> tuple[pd.DataFrame, float, float]:
    """(curve rows without the id, base speed [m/s], spring constant [N/m]) of one curve file."""
    return approach_rows(load_datasets(path, overrides)[0], str(path), speed)


def approach_rows(data, label: str, speed: float | None) -> tuple[pd.DataFrame, float, float]:
    """(curve rows without the id, base speed [m/s], spring constant [N/m]) of one afmformats dataset;
    ``label`` names it in errors."""
    approach = np.asarray(data["segment"]) == 0
    height_column = "height (piezo)" if "height (piezo)" in data.columns else "height (measured)"
    height = np.asarray(data[height_column], dtype=np.float64)[approach]
    force = np.asarray(data["force"], dtype=np.float64)[approach]
    md = data.metadata  # afmformats' metadata raises on .get of a key it lacks
    base_speed = speed or (md["speed approach"] if "speed approach" in md else None)
    if not base_speed:
        raise RecordingError(f"{label}: the file gives no approach speed; pass --speed in m/s")
    spring_constant = float(md["spring constant"])
    travel = np.abs(height - height[0])  # the base moves into the sample
    deepest = int(np.argmax(travel)) + 1
    travel, force = travel[:deepest], force[:deepest]
    try:
        contact_z = estimate_baseline(travel, force, spring_constant).contact_z
    except NoBaseline as error:
        raise RecordingError(
            f"{label}: no baseline before contact ({error}); record the approach from further away"
        ) from None
    if "time" in data.columns:
        time = np.asarray(data["time"], dtype=np.float64)[approach][:deepest]
        time = time - time[0]
    else:
        time = np.linspace(0.0, travel.max() / base_speed, len(travel))
    rows = pd.DataFrame({"base_speed": float(base_speed), "time": time, "z": travel - contact_z, "force": force})
    return rows, float(base_speed), spring_constant


def import_files(files: list[Path], out: Path, meta: dict, speed: float | None, overrides: dict) -> None:
    """One recording set in ``out``, a curve per file."""
    curves = {path.name: approach_curve(path, speed, overrides) for path in files}
    write_set(out, curves, meta)


def import_maps(files: list[Path], out: Path, meta: dict, speed: float | None, overrides: dict) -> list[str]:
    """A force map in ``out`` from force-map files (one per speed, say): a recording set per spot, the spots
    matched across files by their grid index, each with its position. Returns the one-line reason of every
    curve that could not be imported (its spot is written without it, or not at all if none was)."""
    spots: dict[tuple[int, int], dict] = {}
    positions: dict[tuple[int, int], tuple[float, float] | None] = {}
    failures = []
    for path in files:
        for data in load_datasets(path, overrides):
            md = data.metadata
            if "grid index x" not in md or "grid index y" not in md:
                raise RecordingError(
                    f"{path}: not a force map (its curves have no grid index); import it without --map"
                )
            key = (int(md["grid index x"]), int(md["grid index y"]))
            label = f"{path} (spot {key[0]}, {key[1]})"
            try:
                spots.setdefault(key, {})[label] = approach_rows(data, label, speed)
            except RecordingError as error:
                failures.append(str(error))
            has_position = "position x" in md and "position y" in md
            positions[key] = (float(md["position x"]), float(md["position y"])) if has_position else None
    for (column, row), curves in sorted(spots.items()):
        try:
            write_set(out / f"spot_{row:03d}_{column:03d}", curves, meta, positions[(column, row)])
        except RecordingError as error:
            failures.append(str(error))
    return failures


def write_set(out: Path, curves: dict[str, tuple], meta: dict, position: tuple[float, float] | None = None) -> None:
    """Write the recording set of ``curves`` ({source: approach rows, base speed, spring constant}) to
    ``out`` and check it reads back."""
    frames, springs = [], {}
    for source, (rows, base_speed, spring_constant) in curves.items():
        curve = f"v{base_speed * 1e6:.3g}"
        while any(frame["curve"].iloc[0] == curve for frame in frames):
            curve += "b"
        frames.append(rows.assign(curve=curve)[["curve", "base_speed", "time", "z", "force"]])
        springs[Path(source).name] = spring_constant
    if max(springs.values()) > 1.01 * min(springs.values()):
        listing = ", ".join(f"{name} {k:.4g} N/m" for name, k in springs.items())
        raise RecordingError(
            f"spring constants differ ({listing}); a recording set is one cantilever: import them apart"
        )
    slowest = min(frames, key=lambda frame: frame["base_speed"].iloc[0])["curve"].iloc[0]
    write_recordings(
        out,
        Meta(
            spring_constant=next(iter(springs.values())),
            reference_curve=slowest,
            contact_point="estimate",
            notes="imported with ptwin.data.import_afm: " + ", ".join(Path(s).name for s in curves),
            position=position,
            **meta,
        ),
        pd.concat(frames, ignore_index=True),
    )
    load_recordings(out)  # what was written must be a valid set: say so now, not at the first fit


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m ptwin.data.import_afm", description=__doc__.split("\n\n")[1])
    parser.add_argument("files", nargs="+", type=Path)
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--probe-radius", required=True, type=float, help="ρ [m]")
    parser.add_argument("--viscosity", required=True, type=float, help="μ [Pa s]")
    parser.add_argument("--thickness", required=True, type=float, help="H0 [m]")
    parser.add_argument("--sample", default="", help="free text")
    parser.add_argument("--speed", type=float, help="approach speed [m/s] when the files lack it")
    parser.add_argument("--spring-constant", type=float, help="[N/m] when the files lack it")
    parser.add_argument("--sensitivity", type=float, help="[m/V] when the files lack it")
    parser.add_argument(
        "--map", action="store_true", help="the files are force maps (one per speed): write a recording set per spot"
    )
    args = parser.parse_args(argv)
    overrides = {k: v for k, v in (("spring constant", args.spring_constant), ("sensitivity", args.sensitivity)) if v}
    meta = {
        "probe_radius": args.probe_radius,
        "fluid_viscosity": args.viscosity,
        "sample_thickness": args.thickness,
        "sample": args.sample,
    }
    try:
        if not args.map:
            import_files(args.files, args.out, meta, args.speed, overrides)
        else:
            for failure in import_maps(args.files, args.out, meta, args.speed, overrides):
                print(f"not imported: {failure}", file=sys.stderr)
    except RecordingError as error:
        print(error, file=sys.stderr)
        raise SystemExit(2) from None
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main(sys.argv[1:])
