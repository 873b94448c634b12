"""What a hold or a creep shows before any model: how far the force relaxes at constant base
position (a hold, stress relaxation) or the tip sinks at constant force (a creep), and how fast.

The change is read from the approach's last sample (the peak force: the Darcy force drops
when the base stops) to the mean of the segment's last ``TAIL`` (noise averaged out there,
not at the start, where a pore pressure drains in milliseconds), its
standard error from the segment's own scatter (second differences); the half time is where
the change, smoothed over ``SMOOTHING`` samples, first reaches half of it: a relaxation spread
over decades of time (a power law) reaches half late, a single exponential at 0.69 τ. Both
are said only where the change exceeds ``SEEN`` standard errors.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ptwin.data.kinematics import CurveKinematics
from ptwin.data.recordings import APPROACH, CREEP, HOLD

TAIL = 0.1  # fraction of the segment (its end) averaged for the relaxed value
SMOOTHING = 5  # samples of the running mean the half time is read on
SEEN = 3.0  # standard errors a change must exceed to be reported as one


@dataclass(frozen=True)
class Relaxation:
    """One hold (the force [N]) or creep (the depth [m]) from its first sample to its end."""

    curve: str
    kind: str  # "hold" or "creep"
    duration: float  # [s]
    start: float  # the force (hold) or depth (creep) where the approach ended
    end: float  # its mean over the segment's last TAIL
    error: float  # standard error of end − start, same unit
    half_time: float | None  # [s] from the segment's first sample to half the change (None: the change is noise)
    # A creep's force [N] where the approach ended and over its last TAIL: the feedback's to hold, which the
    # sentence shows rather than claims (a hold marked creep relaxed 12% "at constant force"); None for a hold.
    force: tuple[float, float] | None = None

    @property
    def change(self) -> float:
        """The fraction relaxed (hold: the force's fall over its start) or crept (creep: the depth's growth)."""
        return (self.start - self.end) / self.start if self.kind == "hold" else (self.end - self.start) / self.start

    @property
    def seen(self) -> bool:
        return abs(self.end - self.start) > SEEN * self.error

    def sentence(self) -> str:
        if self.kind == "hold":
            what = (
                f"the force relaxes by {100 * self.change:.1f}% over the {self.duration:.3g} s hold "
                f"({self.start * 1e9:.4g} → {self.end * 1e9:.4g} nN)"
            )
        else:
            what = (
                f"the tip sinks by {(self.end - self.start) * 1e6:.3g} µm ({100 * self.change:.1f}% of its depth) over "
                f"the {self.duration:.3g} s creep"
            )
            if self.force is not None:
                first, last = self.force
                what += f" (its force {first * 1e9:.4g} → {last * 1e9:.4g} nN, {100 * (last - first) / first:+.1f}%)"
        if self.kind == "hold" and self.end < -SEEN * self.error:
            # An indenting tip pushes: a held force that ends below the baseline says the baseline removed from
            # the curve (a level and a tilt read off its approach, extended into contact) does not hold there.
            return (
                f"{self.curve}: {what}: it ends below the baseline, which no indentation does; the baseline removed "
                "from this curve (its level and tilt, read off the approach before contact) does not hold in contact, "
                "so the relaxed fraction is not a measurement (a tilt that is a contact force already, or drift)."
            )
        if not self.seen:
            return f"{self.curve}: {what}, within {SEEN:g} standard errors of none."
        return f"{self.curve}: {what}; half of it in the first {self.half_time:.3g} s."


def relaxations(curves: list[CurveKinematics]) -> list[Relaxation]:
    """Every hold and creep of ``curves`` that is in contact, in file order, read from the approach's last
    sample (the peak force of a stress relaxation: the drop of the Darcy force when the base stops is part
    of what relaxes) where the segment follows one, else from its own first sample."""
    found = []
    for curve in curves:
        for code, kind in ((HOLD, "hold"), (CREEP, "creep")):
            mine = np.flatnonzero((curve.segment == code) & (curve.depth > 0))
            if mine.size < 2 * SMOOTHING:
                continue
            values = curve.force if kind == "hold" else curve.depth
            before = mine[0] - 1
            origin = before if before >= 0 and curve.segment[before] == APPROACH else mine[0]
            time = curve.time[mine] - curve.time[mine[0]]
            read = _read(curve.curve, kind, time, float(values[origin]), values[mine])
            if kind == "creep":
                read = replace(
                    read, force=(float(curve.force[origin]), float(curve.force[mine[-_tail(mine.size) :]].mean()))
                )
            found.append(read)
    return found


def _read(curve: str, kind: str, time: np.ndarray, start: float, values: np.ndarray) -> Relaxation:
    # The segment's own scatter (second differences remove any smooth relaxation), in its own unit.
    noise = float(np.std(np.diff(values, 2)) / np.sqrt(6.0))
    tail = _tail(values.size)
    end = float(values[-tail:].mean())
    error = noise * np.sqrt(1.0 + 1.0 / tail)
    smoothed = np.convolve(values, np.ones(SMOOTHING) / SMOOTHING, mode="valid")
    halfway = (smoothed - start) / (end - start) >= 0.5 if end != start else np.zeros(smoothed.size, bool)
    half = time[int(np.argmax(halfway)) + SMOOTHING // 2] if halfway.any() else None
    relaxation = Relaxation(curve, kind, float(time[-1]), start, end, float(error), half)
    return relaxation if relaxation.seen else Relaxation(curve, kind, float(time[-1]), start, end, float(error), None)


def _tail(size: int) -> int:
    """How many of a segment's ``size`` samples its relaxed value is the mean of: its last ``TAIL``, one at least."""
    return max(int(TAIL * size), 1)
