"""Recording sets (contract: shared/recording-format.md): read, validate, write.

Every refusal is one ``RecordingError`` line naming the file, the row (1-based line of
the file) or the curve, and the fix. Nothing is dropped: extra columns are kept, and
pre-contact samples, baseline offsets and unequal final depths are evidence, not errors.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from ptwin.checks import first_line

FORMAT = "ptwin-recordings/1"
COLUMNS = ("curve", "base_speed", "time", "z", "force")
SEGMENTS = ("approach", "hold", "creep", "retract")  # the optional column's values, in the order a curve has them
APPROACH, HOLD, CREEP, RETRACT = range(len(SEGMENTS))  # their codes (``CurveKinematics.segment``)
SPEED_SIGN = {
    "approach": lambda v: v > 0,
    "hold": lambda v: v == 0,
    "creep": lambda v: v == 0,
    "retract": lambda v: v < 0,
}
SPEED_AGREEMENT = 3.0  # the factor z's own rate over an approach may be off its base_speed (imports: 0.90–1.002; a JPK
# piezo height without its sensor, 0.54–0.65)
SPEED_RULE = {
    "approach": "> 0 (into the sample)",
    "hold": "0 (the base is fixed)",
    "creep": "0 (the feedback moves the base: z as recorded)",
    "retract": "< 0 (out of it)",
}
MIN_SAMPLES = 20
# How an import's note in meta.yaml begins where its curves were recorded at several places (``import_afm.places``);
# a run repeats that note in its report (``Meta.places``).
PLACES = "the curves were recorded at "
# Samples in a row at exactly the largest force of the approach and hold: a deflection past the detector's range
# reads as its last value, and no sample holds its force to the last digit while it is pressed.
SATURATED = 10
# Magnitudes no AFM indentation reaches in SI: a value past them is in other units.
_PLAUSIBLE = {"z": (1e-3, "m (micrometres?)"), "force": (1e-3, "N (nanonewtons?)"), "base_speed": (1e-2, "m/s (µm/s?)")}


class RecordingError(ValueError):
    """Bad input in a recording set; the message is the one line to show the user."""


@dataclass
class Meta:
    """The sample, probe and cantilever of a recording set (SI units)."""

    probe_radius: float  # ρ [m]
    spring_constant: float  # k_s [N/m]
    sample_thickness: float  # H0 [m]
    fluid_viscosity: float  # μ [Pa s]
    reference_curve: str
    sample: str = ""
    contact_point: str = "known"
    noise_std: float | None = None  # [N]
    notes: str = ""
    position: tuple[float, float] | None = None  # (x, y) [m]: the spot's place in a force map

    def places(self) -> str | None:
        """The import's note that these curves were recorded at several places (``PLACES`` on), else None."""
        start = self.notes.find(PLACES)
        return self.notes[start:] if start >= 0 else None


# The keys of meta.yaml in the recording format (v1.2): its version and Meta's fields; any other is read by nothing.
KEYS = ("format", *(f.name for f in fields(Meta)))


@dataclass
class RecordingSet:
    """One sample at several base speeds: ``meta`` and the long table ``curves``."""

    path: Path
    meta: Meta
    curves: pd.DataFrame
    unread: tuple[str, ...] = ()  # keys of meta.yaml outside the format (a lab's own), which nothing reads

    @property
    def curve_ids(self) -> list[str]:
        return list(dict.fromkeys(self.curves["curve"]))

    def curve(self, curve_id: str) -> pd.DataFrame:
        return self.curves[self.curves["curve"] == curve_id]


def load_recordings(path: str | Path) -> RecordingSet:
    """Read and validate the recording set in folder ``path``."""
    folder = Path(path)
    if not folder.is_dir():
        raise RecordingError(
            f"{folder}: no such recording-set folder; give data.path=<folder with meta.yaml and curves.csv>"
        )
    meta, unread = _read_meta(folder / "meta.yaml")
    curves = _read_curves(folder / "curves.csv", meta)
    return RecordingSet(folder, meta, curves, unread)


def write_recordings(path: str | Path, meta: Meta, curves: pd.DataFrame) -> None:
    """Write ``meta.yaml`` and ``curves.csv`` (full float precision) into folder ``path``."""
    folder = Path(path)
    folder.mkdir(parents=True, exist_ok=True)
    values = {"format": FORMAT, **{k: v for k, v in asdict(meta).items() if v not in (None, "")}}
    if meta.position is not None:
        values["position"] = [float(c) for c in meta.position]
    (folder / "meta.yaml").write_text(yaml.safe_dump(values, sort_keys=False))
    curves.to_csv(folder / "curves.csv", index=False, float_format="%.17g")


def _read_meta(file: Path) -> tuple[Meta, tuple[str, ...]]:
    """The set's ``Meta``, and the keys outside the format (``KEYS``) it holds besides."""
    if not file.is_file():
        raise RecordingError(f"{file}: missing; a recording set needs meta.yaml beside curves.csv")
    try:
        values = yaml.safe_load(file.read_text())
    except yaml.YAMLError as error:
        raise RecordingError(f"{file}: not valid YAML ({first_line(error)}); fix the syntax") from None
    if not isinstance(values, dict):
        raise RecordingError(f"{file}: expected key: value lines (probe_radius, spring_constant, ...)")
    if values.get("format", FORMAT) != FORMAT:
        raise RecordingError(f"{file}: format {values['format']!r}, this ptwin reads {FORMAT!r}")
    numbers = {}
    for key in ("probe_radius", "spring_constant", "sample_thickness", "fluid_viscosity"):
        if key not in values:
            raise RecordingError(f"{file}: missing key {key!r}; add it in SI units")
        numbers[key] = _positive_number(file, key, values[key])
    if numbers["probe_radius"] > 1e-3:
        raise RecordingError(
            f"{file}: probe_radius {numbers['probe_radius']:g} m is not SI (micrometres?); write e.g. 12.0e-6"
        )
    if numbers["sample_thickness"] > 1.0:
        raise RecordingError(
            f"{file}: sample_thickness {numbers['sample_thickness']:g} m is not SI; write metres, e.g. 6.0e-3"
        )
    if "reference_curve" not in values:
        raise RecordingError(f"{file}: missing key 'reference_curve'; name the slowest curve, e.g. v0.5")
    contact = values.get("contact_point", "known")
    if contact not in ("known", "estimate"):
        raise RecordingError(f"{file}: contact_point {contact!r}; use known or estimate")
    noise = values.get("noise_std")
    noise = None if noise is None else _positive_number(file, "noise_std", noise)
    if noise is not None and noise > _PLAUSIBLE["force"][0]:
        raise RecordingError(f"{file}: noise_std {noise:g} N is not SI (nanonewtons?); write newtons, e.g. 2.0e-10")
    meta = Meta(
        **numbers,
        reference_curve=str(values["reference_curve"]),
        sample=str(values.get("sample", "")),
        contact_point=contact,
        noise_std=noise,
        notes=str(values.get("notes", "")),
        position=_position(file, values.get("position")),
    )
    return meta, _outside_format(file, values)


def _outside_format(file: Path, values: dict) -> tuple[str, ...]:
    """The keys of ``values`` outside the format: a lab's own are kept (and said unread), but one spelt like a key of
    the format it lacks is refused, a misspelt optional key (``noise_sd``, ``contact_piont``) having run unread."""
    outside = tuple(str(key) for key in values if key not in KEYS)
    for key in outside:
        meant = difflib.get_close_matches(key, [k for k in KEYS if k not in values], n=1, cutoff=0.8)
        if meant:
            raise RecordingError(
                f"{file}: {key!r} is no key of the recording format, so nothing would read it; "
                f"did you mean {meant[0]!r}?"
            )
    return outside


def _position(file: Path, value) -> tuple[float, float] | None:
    if value is None:
        return None
    try:
        x, y = (float(c) for c in value)
    except (TypeError, ValueError):
        raise RecordingError(f"{file}: position {value!r} is not [x, y]; write two numbers in metres") from None
    if not (math.isfinite(x) and math.isfinite(y)) or max(abs(x), abs(y)) > 1e-2:
        raise RecordingError(f"{file}: position {value!r} is not a place on a sample in metres; write e.g. [5.0e-6, 0]")
    return x, y


def _positive_number(file: Path, key: str, value) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise RecordingError(f"{file}: {key} {value!r} is not a number; write it in SI units, e.g. 1.0e-3") from None
    if not math.isfinite(number) or number <= 0:
        raise RecordingError(f"{file}: {key} must be a positive finite number, got {value!r}")
    return number


def _read_curves(file: Path, meta: Meta) -> pd.DataFrame:
    if not file.is_file():
        raise RecordingError(f"{file}: missing; a recording set needs curves.csv beside meta.yaml")
    try:
        frame = pd.read_csv(file, dtype=str, keep_default_na=False)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as error:
        raise RecordingError(
            f"{file}: not a readable CSV ({first_line(error)}); one header line, comma separated"
        ) from None
    missing = [c for c in COLUMNS if c not in frame.columns]
    if missing:
        raise RecordingError(
            f"{file}: missing column(s) {', '.join(missing)}; the header must hold {', '.join(COLUMNS)}"
        )
    if frame.empty:
        raise RecordingError(f"{file}: no samples below the header")
    frame["curve"] = frame["curve"].str.strip()
    if "segment" in frame:
        frame["segment"] = frame["segment"].str.strip()
        bad = ~frame["segment"].isin(SEGMENTS)
        if bad.any():
            row = int(np.argmax(bad.to_numpy()))
            raise RecordingError(
                f"{file}: row {row + 2}, column segment: {frame['segment'].iloc[row]!r}; use "
                f"{', '.join(SEGMENTS[:-1])} or {SEGMENTS[-1]}"
            )
    for column in COLUMNS[1:]:
        values = pd.to_numeric(frame[column].str.strip(), errors="coerce")
        bad = ~np.isfinite(values.to_numpy(dtype=float))
        if bad.any():
            row = int(np.argmax(bad))
            raise RecordingError(
                f"{file}: row {row + 2}, column {column}: {frame[column].iloc[row]!r} is not a finite number; "
                "fix or remove the row"
            )
        frame[column] = values.astype(np.float64)
        limit, unit = _PLAUSIBLE.get(column, (None, None))
        if limit is not None and frame[column].abs().max() > limit:
            row = int(frame[column].abs().to_numpy().argmax())
            raise RecordingError(
                f"{file}: row {row + 2}, column {column}: {frame[column].iloc[row]:g} is not SI {unit}; convert to SI"
            )
    _check_curves(file, frame, meta)
    return frame


def _check_curves(file: Path, frame: pd.DataFrame, meta: Meta) -> None:
    ids = frame["curve"].to_numpy()
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    first_seen = {}
    for start in starts:
        curve = ids[start]
        if curve == "":
            raise RecordingError(f"{file}: row {start + 2}: empty curve id; give every row its curve id")
        if curve in first_seen:
            raise RecordingError(
                f"{file}: row {start + 2}: curve {curve!r} resumes after another curve; keep each curve's rows together"
            )
        first_seen[curve] = start
    for start, stop in zip(starts, np.r_[starts[1:], len(frame)]):
        _check_curve(file, frame.iloc[start:stop], start, meta)
    if meta.reference_curve not in first_seen:
        raise RecordingError(
            f"{file.parent / 'meta.yaml'}: reference_curve {meta.reference_curve!r} is not a curve of curves.csv "
            f"(curves: {', '.join(sorted(first_seen))})"
        )


def _check_curve(file: Path, rows: pd.DataFrame, start: int, meta: Meta) -> None:
    """One curve's rows (``start``: the index of its first row in the file's table)."""
    curve = rows["curve"].iloc[0]
    if len(rows) < MIN_SAMPLES:
        raise RecordingError(f"{file}: curve {curve!r} has {len(rows)} samples, at least {MIN_SAMPLES} are needed")
    step = np.diff(rows["time"].to_numpy())
    if (step <= 0).any():
        row = start + int(np.argmax(step <= 0)) + 1
        raise RecordingError(
            f"{file}: row {row + 2}, curve {curve!r}: time does not increase; sort the curve by time or fix the row"
        )
    _check_segments(file, rows, start)
    _check_saturated(file, rows, start)
    depth = rows["z"].to_numpy() - rows["force"].to_numpy() / meta.spring_constant
    if depth.max() >= meta.sample_thickness:
        row = start + int(depth.argmax())
        raise RecordingError(
            f"{file}: row {row + 2}, curve {curve!r}: depth {depth.max():.3g} m reaches the sample thickness "
            f"{meta.sample_thickness:.3g} m; check sample_thickness in meta.yaml (and z, force, spring constant)"
        )
    if depth.max() > meta.probe_radius:
        row = start + int(depth.argmax())
        raise RecordingError(
            f"{file}: row {row + 2}, curve {curve!r}: depth {depth.max():.3g} m exceeds the probe radius "
            f"{meta.probe_radius:.3g} m; check probe_radius in meta.yaml (and z, force, spring constant)"
        )


def _segment_names(rows: pd.DataFrame) -> np.ndarray:
    """Each row's segment; absent, every row an approach."""
    return rows["segment"].to_numpy() if "segment" in rows else np.full(len(rows), SEGMENTS[0])


def _check_saturated(file: Path, rows: pd.DataFrame, start: int) -> None:
    """No ``SATURATED`` samples in a row at the largest force of the approach and hold, above where it began."""
    names = _segment_names(rows)
    pressed = np.flatnonzero(np.isin(names, SEGMENTS[:CREEP]))
    force = rows["force"].to_numpy()[pressed]
    if force.size == 0 or force.max() <= force[0]:
        return
    edges = np.diff(np.r_[0, (force == force.max()).astype(int), 0])
    begins, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    longest = int(np.argmax(ends - begins))
    if ends[longest] - begins[longest] >= SATURATED:
        first, last = (start + int(pressed[i]) + 2 for i in (begins[longest], ends[longest] - 1))
        curve, largest = rows["curve"].iloc[0], force.max()
        raise RecordingError(
            f"{file}: rows {first}–{last}, curve {curve!r}: the force stays at {largest:.6g} N, its largest, to the "
            "last digit while the probe presses: the detector saturated; record with a lower setpoint (trigger "
            "force), or leave the curve out"
        )


def _check_segments(file: Path, rows: pd.DataFrame, start: int) -> None:
    """Segments in time order (approach, hold, creep, retract), each contiguous, at one base speed: > 0 on the
    approach, 0 in a hold or a creep, < 0 on the retract."""
    curve = rows["curve"].iloc[0]
    names = _segment_names(rows)
    order = np.array([SEGMENTS.index(name) for name in names])
    if (np.diff(order) < 0).any():
        row = start + int(np.argmax(np.diff(order) < 0)) + 1
        raise RecordingError(
            f"{file}: row {row + 2}, curve {curve!r}: segment {names[row - start]!r} comes after "
            f"{names[row - start - 1]!r}; a curve's segments run approach, hold, creep, retract"
        )
    speeds = rows["base_speed"].to_numpy()
    for code, name in enumerate(SEGMENTS):
        mine = order == code
        if not mine.any():
            continue
        first = start + int(np.argmax(mine))
        changed = mine & ~np.isclose(speeds, speeds[mine][0], rtol=1e-9, atol=0)
        if changed.any():
            raise RecordingError(
                f"{file}: row {start + int(np.argmax(changed)) + 2}, curve {curve!r}: base_speed changes within the "
                f"{name}; one nominal speed per segment (mark a hold with segment: hold)"
            )
        if not SPEED_SIGN[name](speeds[mine][0]):
            raise RecordingError(
                f"{file}: row {first + 2}, curve {curve!r}: base_speed {speeds[mine][0]:g} on the {name}; it must be "
                f"{SPEED_RULE[name]}"
            )
        if name == "approach":
            _check_approach_speed(file, rows[mine], first, speeds[mine][0])


def _check_approach_speed(file: Path, rows: pd.DataFrame, first: int, speed: float) -> None:
    """z's own rate over the approach (end to end) against its nominal ``speed`` [m/s]: more than a factor
    ``SPEED_AGREEMENT`` apart, one of the two is wrong (a speed in mm/s, z from another channel, a base that never
    moved), and the speed labels the curve, its drag and the experiments proposed."""
    time, z = rows["time"].to_numpy(), rows["z"].to_numpy()
    if len(time) < 2:
        return
    moved = (z[-1] - z[0]) / (time[-1] - time[0])
    if not 1 / SPEED_AGREEMENT <= moved / speed <= SPEED_AGREEMENT:
        raise RecordingError(
            f"{file}: row {first + 2}, curve {rows['curve'].iloc[0]!r}: base_speed {speed:g} m/s on the approach, "
            f"but z advances at {moved:.3g} m/s over it; give the speed the base moves at, or fix z and time"
        )
