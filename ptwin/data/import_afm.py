"""python -m ptwin.data.import_afm FILES... --out DIR --probe-radius R --viscosity MU --thickness H0 [--map]

Vendor AFM files (JPK .jpk-force, Asylum .ibw, NT-MDT text and whatever afmformats
reads; JPK's text exports, which it does not, through ``ptwin.data.jpk_text``) into one
recording set, one curve per file: force-distance, stress-relaxation and creep-compliance
curves alike, sets mixing them too. With ``--map``, force-map files (e.g.
JPK .jpk-force-map, one per speed or protocol) into a force map: a recording set per spot,
spots matched across the files by their grid index, each with its position. What no file
knows (probe radius, fluid viscosity, sample thickness, and for some formats the spring
constant, sensitivity or speed) comes from the command line.

Each segment is kept for what the file's imaging mode says it is (recording format v1.2):
the approach (cut at the deepest base position: some files, e.g. Asylum .ibw, store
approach and retract as one segment), a hold at constant height (stress relaxation), a creep
at constant force (creep compliance; z as the sensor recorded it, base speed 0). A stress
relaxation's leading pause and every retract are not written (meta.yaml's notes and the
command's output say so). The force is kept raw (its baseline offset is evidence).

z is the base travel from the contact estimated by ``ptwin.data.contact`` on the approach
(z < 0 before it), read off the sensor-measured height where the file has one; meta.yaml
says ``contact_point: estimate``, so every run estimates each curve's contact and baseline
again and refines it in the fit. Time: the file's own (from the approach's start), else
uniform over travel / approach speed (an approach alone).
"""

from __future__ import annotations

import argparse
import itertools
import logging
import math
import os
import shutil
import string
import sys
from dataclasses import dataclass
from pathlib import Path

import afmformats
import numpy as np
import pandas as pd

from ptwin.data import jpk_text
from ptwin.data.contact import NoBaseline, estimate_baseline
from ptwin.data.recordings import PLACES, Meta, RecordingError, load_recordings, write_recordings

# What each segment of a curve is, by the imaging mode afmformats reads from the file (its segment order):
# a stress relaxation's leading pause at constant height is baseline, not the approach.
SEGMENTS_OF = {
    "force-distance": ("approach", "retract"),
    "creep-compliance": ("approach", "creep", "retract"),
    "stress-relaxation": ("pause", "approach", "hold", "retract"),
}
KEPT = ("approach", "hold", "creep")  # written; the pause and the retract are said to be left out
SUFFIX = {"hold": "h", "creep": "c"}  # of a curve's id, for what follows its approach
# The sensor-measured base position where the file has one (JPK's strain gauge: its travel is the approach
# speed × duration, the piezo's "height" 54–65% of it on every JPK file in ../shared/data/afm); nanite and
# JPK's own "Vertical Tip Position" use it too.
HEIGHT = "height (measured)"
# Positions closer than this [m] are one place: a map's spot repeats its position to ~1e-12 m, a stage's to ~10 nm.
SAME_PLACE = 1e-7


def load_datasets(path: Path, overrides: dict) -> list:
    """Every force-distance dataset afmformats reads from ``path`` (one for a curve file, one per spot and
    curve for a force map); JPK's text exports, which it does not read, through ``ptwin.data.jpk_text``."""
    if path.is_dir():  # afmformats says "not a format it reads" of a folder or a path that is not there
        raise RecordingError(f"{path}: a folder; give the curve files in it (e.g. {path}/*.jpk-force)")
    if not path.is_file():
        raise RecordingError(f"{path}: no such file; check the path (quote a name with spaces)")
    if jpk_text.is_text_export(path):
        return jpk_text.load(path, overrides, SEGMENTS_OF)
    quiet = logging.getLogger("afmformats")
    level, quiet.level = quiet.level, logging.CRITICAL  # it logs a traceback for every error it then raises
    try:
        return afmformats.load_data(path, meta_override=overrides)
    except afmformats.errors.MissingMetaDataError as error:  # a BaseException, not an Exception
        options = " and ".join(f"--{key.replace(' ', '-')}" for key in error.meta_keys)
        raise RecordingError(f"{path}: the file gives no {' or '.join(error.meta_keys)}; pass {options}") from None
    except afmformats.errors.FileFormatNotSupportedError:  # a BaseException too
        raise RecordingError(
            f"{path}: not a format afmformats reads; export the curve as JPK .jpk-force, Asylum .ibw, NT-MDT text or "
            "another format afmformats lists"
        ) from None
    except (Exception, afmformats.errors.AFMFileFormatError) as error:  # afmformats' are BaseExceptions
        raise RecordingError(f"{path}: afmformats cannot read it ({error}); check the file and its format") from None
    finally:
        quiet.setLevel(level)


def curve_file(path: Path, speed: float | None, overrides: dict) -> tuple[tuple, Place | None]:
    """(``curve_rows`` of the curve in file ``path``, where it was recorded); a file of several curves (a force
    map) is refused, never read for its first alone."""
    datasets = load_datasets(path, overrides)
    if len(datasets) > 1:
        mapped = all("grid index x" in data.metadata for data in datasets)
        fix = "import it with --map (a recording set per spot)" if mapped else "export its curves to files of one each"
        raise RecordingError(f"{path}: {len(datasets)} curves in one file; {fix}")
    return curve_rows(datasets[0], str(path), speed), Place.of(datasets[0].metadata)


@dataclass(frozen=True)
class Place:
    """Where a file says its curve was recorded: a position [m] in the frame of its session (afmformats' dataset
    identifier, JPK's map run: the speeds of one public map share it), which another session's need not share."""

    x: float
    y: float
    session: str | None

    @classmethod
    def of(cls, md) -> Place | None:
        if "position x" not in md or "position y" not in md:
            return None
        return cls(float(md["position x"]), float(md["position y"]), md["session id"] if "session id" in md else None)

    def same(self, other: Place) -> bool:
        return self.session == other.session and math.dist((self.x, self.y), (other.x, other.y)) <= SAME_PLACE

    def words(self) -> str:
        x, y = (f"{round(c * 1e6, 2) + 0.0:g}" for c in (self.x, self.y))  # + 0.0: no "-0"
        return f"({x}, {y}) µm" + (f" of session {self.session}" if self.session else "")


def curve_rows(data, label: str, speed: float | None) -> tuple[pd.DataFrame, float, float, str]:
    """(curve rows without the id, with their ``segment``, base speed [m/s], spring constant [N/m], what was
    left out, in words) of one afmformats dataset; ``label`` names it in errors. Each segment is what the
    dataset's imaging mode says it is (``SEGMENTS_OF``)."""
    md = data.metadata  # afmformats' metadata raises on .get of a key it lacks
    mode = md["imaging mode"] if "imaging mode" in md else "force-distance"
    if mode not in SEGMENTS_OF:
        raise RecordingError(f"{label}: a {mode!r} recording; ptwin imports {', '.join(SEGMENTS_OF)} curves")
    kinds = SEGMENTS_OF[mode]
    codes = np.asarray(data["segment"]).astype(int)
    if codes.max() >= len(kinds):
        raise RecordingError(f"{label}: {codes.max() + 1} segments, a {mode} curve has {len(kinds)}; check the file")
    kind = np.array(kinds)[codes]
    base_speed = speed or (md["speed approach"] if "speed approach" in md else None)
    if not base_speed:
        raise RecordingError(f"{label}: the file gives no approach speed; pass --speed in m/s")
    if "spring constant" not in md:  # a file whose force column needs none (AFM Workshop's CSV) may lack it
        raise RecordingError(f"{label}: the file gives no spring constant; pass --spring-constant in N/m")
    spring_constant = float(md["spring constant"])
    height = np.asarray(data[HEIGHT if HEIGHT in data.columns else "height (piezo)"], dtype=np.float64)
    force = np.asarray(data["force"], dtype=np.float64)
    approach = np.flatnonzero(kind == "approach")
    travel = (height - height[approach[0]]) * np.sign(height[approach[-1]] - height[approach[0]])
    if np.ptp(travel[approach]) == 0:  # a recording cut short (nanite's test files hold approaches of 1–3 samples)
        raise RecordingError(
            f"{label}: its approach is {approach.size} sample(s) over no travel, not a curve; record it again"
        )
    # Some files (Asylum .ibw) store approach and retract as one segment: the approach ends at its deepest.
    retracting = approach[int(np.argmax(travel[approach])) + 1 :]
    kind[retracting] = "retract"
    approach = np.flatnonzero(kind == "approach")
    try:
        contact_z = estimate_baseline(travel[approach], force[approach], spring_constant).contact_z
    except NoBaseline as error:
        raise RecordingError(
            f"{label}: no baseline before contact ({error}); record the approach from further away"
        ) from None
    kept = np.flatnonzero(np.isin(kind, KEPT) & (np.arange(kind.size) >= approach[0]))
    if "time" in data.columns:
        time = np.asarray(data["time"], dtype=np.float64)
    elif np.any(kind[kept] != "approach"):
        raise RecordingError(f"{label}: a {mode} curve without its time column; export it with time")
    else:
        time = np.interp(np.arange(kind.size), approach[[0, -1]], [0.0, np.ptp(travel[approach]) / base_speed])
    rows = pd.DataFrame(
        {
            "base_speed": np.where(kind[kept] == "approach", float(base_speed), 0.0),
            "time": time[kept] - time[approach[0]],
            "z": travel[kept] - contact_z,
            "force": force[kept],
            "segment": kind[kept],
        }
    )
    left = [f"the {name} ({int(np.sum(kind == name))} samples)" for name in dict.fromkeys(kind) if name not in KEPT]
    left += [md[jpk_text.LEFT_OUT]] if jpk_text.LEFT_OUT in md else []
    return rows, float(base_speed), spring_constant, " and ".join(left)


def import_files(files: list[Path], out: Path, meta: dict, speed: float | None, overrides: dict) -> str:
    """One recording set in ``out``, a curve per file; which file became which curve, in words, and where the files
    say their curves were recorded at different places, that (``places``)."""
    read = {path.name: curve_file(path, speed, overrides) for path in files}
    found = {name: place for name, (_, place) in read.items() if place is not None}
    spread = places(found)
    one = next(iter(found.values())) if found and not spread and len(found) == len(read) else None
    curves = {name: rows for name, (rows, _) in read.items()}
    return write_set(out, curves, meta, None if one is None else (one.x, one.y), spread)


def places(found: dict[str, Place]) -> str:
    """Where ``found`` ({file: where it was recorded}) holds more than one place (``SAME_PLACE`` apart, or another
    session), what that does to a diagnosis and what to do, in words; else "". A recording set is one spot: a
    stiffer or softer place reads as a rate effect between its curves (a null set's spots ±10% in stiffness leave
    structure no term explains): public PAAm curves of one file index at three speeds, from three places of two
    maps, were "unexplained" as recorded and with 3 Pa·s of viscosity added; at one place, 5 Pa·s added was named
    with its size at 3 of 4 places."""
    distinct: list[Place] = []
    for place in found.values():
        if not any(place.same(seen) for seen in distinct):
            distinct.append(place)
    if len(distinct) < 2:
        return ""
    listing = ", ".join(f"{name} at {place.words()}" for name, place in found.items())
    return (
        f"{PLACES}{len(distinct)} places ({listing}; another session's positions need not share "
        "its frame): a recording set is one spot, and what differs between places (the sample's heterogeneity) reads "
        "as structure no term explains; import the curves of one place together (--map for force-map files)"
    )


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
                spots.setdefault(key, {})[label] = curve_rows(data, label, speed)
            except RecordingError as error:
                failures.append(str(error))
            place = Place.of(md)
            positions[key] = None if place is None else (place.x, place.y)
    for (column, row), curves in sorted(spots.items()):
        try:
            write_set(out / f"spot_{row:03d}_{column:03d}", curves, meta, positions[(column, row)])
        except RecordingError as error:
            failures.append(str(error))
    return failures


def _unused(curve: str, taken: set[str]) -> str:
    """``curve``, or where a curve of the set has that id, a replicate's: the first of ``curve`` + b, c, …, z, then
    + bb, bc, … that none has (the contract's v5, v5b, v5c)."""
    letters = string.ascii_lowercase[1:]
    ids = (curve + "".join(p) for n in itertools.count() for p in itertools.product(letters, repeat=n))
    return next(i for i in ids if i not in taken)


def write_set(
    out: Path, curves: dict[str, tuple], meta: dict, position: tuple[float, float] | None = None, caveat: str = ""
) -> str:
    """Write the recording set of ``curves`` ({source: ``curve_rows``}) to ``out``, check it reads back, and
    say which file became which curve and what was not written (and ``caveat``, in meta.yaml's notes too). A curve
    is named by its speed and what follows its approach: v20h (a hold), v10c (a creep)."""
    frames, springs, notes = [], {}, []
    for source, (rows, base_speed, spring_constant, left) in curves.items():
        after = [SUFFIX[kind] for kind in dict.fromkeys(rows["segment"]) if kind in SUFFIX]
        curve = _unused(f"v{base_speed * 1e6:.3g}" + "".join(after), {frame["curve"].iloc[0] for frame in frames})
        frames.append(rows.assign(curve=curve)[["curve", "base_speed", "time", "z", "force", "segment"]])
        springs[Path(source).name] = spring_constant
        notes.append(f"{Path(source).name} as {curve}" + (f" ({left} not written)" if left else ""))
    if max(springs.values()) > 1.01 * min(springs.values()):
        listing = ", ".join(f"{name} {k:.4g} N/m" for name, k in springs.items())
        raise RecordingError(
            f"spring constants differ ({listing}); a recording set is one cantilever: import them apart"
        )
    slowest = min(frames, key=lambda frame: frame["base_speed"].iloc[0])["curve"].iloc[0]
    # Written beside ``out`` and read back there first: a set that fails its check never lands (a map's spot
    # folder left behind was run by the map as if imported), and a set already at ``out`` stays as it was.
    target = out.resolve()  # a name of its own, "." too
    staged = target.with_name(f".{target.name}.importing")
    shutil.rmtree(staged, ignore_errors=True)
    write_recordings(
        staged,
        Meta(
            spring_constant=next(iter(springs.values())),
            reference_curve=slowest,
            contact_point="estimate",
            notes="imported with ptwin.data.import_afm: " + "; ".join([*notes, *([caveat] if caveat else [])]),
            position=position,
            **meta,
        ),
        pd.concat(frames, ignore_index=True),
    )
    try:
        load_recordings(staged)
    except RecordingError as error:
        shutil.rmtree(staged)
        raise RecordingError(
            f"{out}: not written: {str(error).removeprefix(f'{staged}{os.sep}')}; meta.yaml's values come from the "
            "import's --probe-radius, --spring-constant, --thickness and --viscosity"
        ) from None
    out.mkdir(parents=True, exist_ok=True)
    for file in staged.iterdir():
        file.replace(out / file.name)
    staged.rmdir()
    return "; ".join(notes) + (f"\nnote: {caveat}" if caveat else "")


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
            print(import_files(args.files, args.out, meta, args.speed, overrides))
        else:
            for failure in import_maps(args.files, args.out, meta, args.speed, overrides):
                print(f"not imported: {failure}", file=sys.stderr)
    except RecordingError as error:
        print(error, file=sys.stderr)
        raise SystemExit(2) from None
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main(sys.argv[1:])
