"""JPK's text export of a force curve (``force-save-*.txt``, JPK Data Processing's export as text): the way many
labs share JPK curves, and one afmformats does not read. Read here into what ``ptwin.data.import_afm`` takes from
afmformats for a JPK file: the columns force [N], height (measured) and (piezo) [m], time [s] and segment (a code
into the segments of its imaging mode), and the metadata imaging mode, spring constant [N/m], sensitivity [m/V]
and approach speed [m/s].

The export is a block per segment: a header of ``# key: value`` lines (the instrument's force settings, then the
segment's kind, columns, units, spring constant and sensitivity), then whitespace-separated rows. The force is the
vertical deflection in whatever unit the export chose (N, m or V: times the spring constant, and the sensitivity).
A pause is a hold where the instrument held the height (stress relaxation), a creep where it held the force (creep
compliance), as its segment settings say; the approach speed is the extend's z travel over its duration, as
afmformats reads it from JPK's own files. A multi-step protocol (extend, pause, extend, pause, ...) is read for its
first step, a ramp and hold of its own (the contract has one approach a curve); the later steps are said to be
left out.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ptwin.data.recordings import RecordingError

FIRST_LINE = "# TEXT EXPORT"
# The sensor-measured base position, the first of these the export has (what afmformats calls height (measured)).
MEASURED_HEIGHT = (
    "smoothedMeasuredHeight",
    "measuredHeight",
    "smoothedStrainGaugeHeight",
    "strainGaugeHeight",
    "smoothedCapacitiveSensorHeight",
    "capacitiveSensorHeight",
)
LEFT_OUT = "left out"  # metadata: what of the file the curve does not hold, in words (afmformats has no such key)
PAUSES = {"constant-height": "hold", "constant-force": "creep"}  # what the instrument held during a pause
# A curve's imaging mode by what follows its approach (force-distance where neither does).
MODE_OF = {"hold": "stress-relaxation", "creep": "creep-compliance"}


def is_text_export(path: Path) -> bool:
    """Whether ``path`` is a JPK text export (its first line says so)."""
    try:
        with open(path, encoding="latin-1") as file:
            return file.readline().strip() == FIRST_LINE
    except OSError:
        return False


class TextExport:
    """One curve of a text export, as ``import_afm.curve_rows`` reads an afmformats dataset: ``metadata`` and
    columns by name."""

    def __init__(self, columns: dict[str, np.ndarray], metadata: dict):
        self._columns, self.metadata = columns, metadata

    @property
    def columns(self) -> list[str]:
        return list(self._columns)

    def __getitem__(self, name: str) -> np.ndarray:
        return self._columns[name]


def load(path: Path, overrides: dict, segments_of: dict[str, tuple[str, ...]]) -> list[TextExport]:
    """The curve in the text export ``path``; ``overrides``: spring constant [N/m] and sensitivity [m/V] in place
    of the file's (the force scaled to them); ``segments_of``: the segments of each imaging mode, in the order its
    ``segment`` column counts them (``ptwin.data.import_afm.SEGMENTS_OF``, afmformats')."""
    blocks = _blocks(path)
    kinds = [_kind(header, path) for header, _ in blocks]
    extends = [i for i, kind in enumerate(kinds) if kind == "approach"]
    if not extends:
        raise RecordingError(f"{path}: no extend segment; a curve needs its approach")
    later = blocks[extends[1] :] if len(extends) > 1 else []
    if later:  # a multi-step protocol: its first step is a ramp and hold (or creep) of its own
        blocks, kinds = blocks[: extends[1]], kinds[: extends[1]]
    mode = next((MODE_OF[kind] for kind in kinds if kind in MODE_OF), "force-distance")
    order = segments_of[mode]
    if any(kind not in order for kind in kinds):
        raise RecordingError(f"{path}: segments {', '.join(kinds)}; a {mode} curve has {', '.join(order)}")
    header = blocks[extends[0]][0]
    spring_constant = overrides.get("spring constant", header.get("springConstant"))
    if spring_constant is None:
        raise RecordingError(f"{path}: the export gives no springConstant; pass --spring-constant in N/m")
    spring_constant, sensitivity = float(spring_constant), overrides.get("sensitivity", header.get("sensitivity"))
    parts = [_columns(h, rows, path, spring_constant, sensitivity) for h, rows in blocks]
    columns = {name: np.concatenate([part[name] for part in parts]) for name in parts[0]}
    columns["segment"] = np.concatenate(
        [np.full(len(rows), order.index(kind)) for (_, rows), kind in zip(blocks, kinds)]
    )
    metadata = {"imaging mode": mode, "spring constant": spring_constant}
    if sensitivity is not None:
        metadata["sensitivity"] = float(sensitivity)
    speed = _approach_speed(header)
    if speed:
        metadata["speed approach"] = speed
    if later:
        samples = sum(len(rows) for _, rows in later)
        steps = f"{len(extends) - 1} later step" + ("s" if len(extends) > 2 else "")
        metadata[LEFT_OUT] = f"the {steps} and what follows ({samples} samples)"
    return [TextExport(columns, metadata)]


def _blocks(path: Path) -> list[tuple[dict[str, str], np.ndarray]]:
    """(header, rows) of each segment, in the file's order; a row that is not as many numbers as its segment's
    columns is refused, naming its line."""
    blocks, header, rows, first = [], {}, [], 0

    def close():
        if rows:
            try:
                values = np.loadtxt(io.StringIO("".join(rows)), ndmin=2)
            except ValueError:
                values = None
            width = len(header.get("columns", "").split())
            if values is None or values.shape[1] != width:
                line = first + next(i for i, row in enumerate(rows) if not _numbers(row, width))
                raise RecordingError(
                    f"{path}: line {line} is not {width} numbers (the columns of segment {header.get('segment')}); "
                    "check the export"
                )
            blocks.append((dict(header), values))
            rows.clear()

    with open(path, encoding="latin-1") as file:
        for number, line in enumerate(file, start=1):
            if line.startswith("#"):
                close()
                key, colon, value = line[1:].partition(":")
                if colon:
                    header[key.strip()] = value.strip()
            elif line.strip():
                first = first if rows else number
                rows.append(line)
    close()
    if not blocks:
        raise RecordingError(f"{path}: a JPK text export without rows; export the curve again with its data")
    return blocks


def _numbers(row: str, width: int) -> bool:
    """Whether ``row`` is ``width`` numbers."""
    fields = row.split()
    try:
        np.array(fields, dtype=np.float64)
    except ValueError:
        return False
    return len(fields) == width


def _kind(header: dict[str, str], path: Path) -> str:
    """What a segment is: the approach (extend), a hold or creep (a pause, by what it held), a retract, or a
    pause before the approach (``load`` refuses a pause that is neither)."""
    segment = header.get("segment", "")
    if segment == "extend":
        return "approach"
    if segment == "retract":
        return "retract"
    if segment != "pause":
        raise RecordingError(f"{path}: a segment {segment!r}; a JPK curve's are extend, pause and retract")
    index = header.get("segmentIndex", "0")
    if int(index) == 0:
        return "pause"
    held = header.get(f"force-settings.segment.{index}.pause-option.type", "")
    if held not in PAUSES:
        raise RecordingError(
            f"{path}: pause segment {index} held {held or 'what the export does not say'}; "
            "ptwin reads pauses at constant height (stress relaxation) or force (creep compliance)"
        )
    return PAUSES[held]


def _columns(header: dict[str, str], rows: np.ndarray, path: Path, spring_constant: float, sensitivity):
    """force [N], height (measured), height (piezo) [m] and time [s] of one segment's rows, under the spring
    constant [N/m] and sensitivity [m/V] in use (None: none known)."""
    names, units = header.get("columns", "").split(), header.get("units", "").split()
    if len(units) != len(names):
        raise RecordingError(f"{path}: {len(units)} units for {len(names)} columns; check the export")
    column = dict(zip(names, rows.T))
    unit = dict(zip(names, units))
    missing = [name for name in ("vDeflection", "height", "seriesTime") if name not in column]
    if missing:
        raise RecordingError(f"{path}: no {', '.join(missing)} column; export the curve with it")
    deflection = unit["vDeflection"]
    if deflection not in ("N", "m", "V"):
        raise RecordingError(f"{path}: vDeflection in {deflection}; export it in N, m or V")
    measured = next((name for name in MEASURED_HEIGHT if name in column and unit[name] == "m"), "height")
    return {
        "force": column["vDeflection"] * _to_newton(deflection, header, spring_constant, sensitivity, path),
        "height (measured)": column[measured],
        "height (piezo)": column["height"],
        "time": column["seriesTime"],
    }


def _to_newton(deflection: str, header: dict[str, str], spring_constant: float, sensitivity, path: Path) -> float:
    """Force [N] per unit of the exported deflection (N, m or V) under the spring constant [N/m] and sensitivity
    [m/V] in use. The export made its m as V × its sensitivity and its N as m × its spring constant, each scaled
    here to the one in use; where it does not give its own, it used the one in use."""
    if deflection == "V":
        if sensitivity is None:
            raise RecordingError(f"{path}: vDeflection in V and no sensitivity; pass --sensitivity in m/V")
        return float(sensitivity) * spring_constant
    metres = 1.0 / float(header.get("springConstant", spring_constant)) if deflection == "N" else 1.0
    if sensitivity is not None and "sensitivity" in header:
        metres *= float(sensitivity) / float(header["sensitivity"])
    return metres * spring_constant


def _approach_speed(header: dict[str, str]) -> float | None:
    """The extend's z travel over its duration [m/s] (segmented settings; relative ones: z start over the extend
    time), None where the header lacks them."""
    index = header.get("segmentIndex")
    segmented = tuple(f"force-settings.segment.{index}.{key}" for key in ("z-start", "z-end", "duration"))
    relative = ("force-settings.relative-z-start", "force-settings.relative-z-end", "force-settings.extend-scan-time")
    for start, end, duration in (segmented, relative):
        if start in header and end in header and duration in header and float(header[duration]) > 0:
            return abs(float(header[start]) - float(header[end])) / float(header[duration])
    return None
