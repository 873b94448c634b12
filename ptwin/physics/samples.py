"""Samples: the recorded curves as flat float64 tensors, ready for the force models.

Curves are concatenated in time order; ``start`` marks the first sample of each, so
hereditary terms (recursions over time) restart there. Every sample is kept: a model
runs over whole curves (the history matters) and fits choose samples by index.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields

import numpy as np
import torch

from ptwin.data.kinematics import CurveKinematics


@dataclass
class Samples:
    """Per-sample tensors of shape (S,), SI units."""

    time: torch.Tensor  # [s] since the start of the curve
    depth: torch.Tensor  # recorded indentation depth w [m]
    velocity: torch.Tensor  # U = dw/dt [m/s]
    base_speed: torch.Tensor  # of the cantilever base, z-dot [m/s] (0 in a hold)
    force: torch.Tensor  # measured force [N] (0 where none was measured)
    start: torch.Tensor  # bool: first sample of a curve
    curve: torch.Tensor  # long: index into ``curve_ids``
    in_contact: torch.Tensor  # bool: samples in contact (w > 0, not on a retract)
    noise_floor: torch.Tensor  # [N], the std of the sample's residual noise: its curve's σ × ``noise_gain``
    curve_ids: tuple[str, ...]
    noise_inflation: float = 1.0  # κ² of the set's noise: block-mean variance over the white expectation
    segment: torch.Tensor | None = None  # long: 0 approach, 1 hold, 2 retract (None: all approach)
    nominal_speed: torch.Tensor | None = None  # the curve's approach speed [m/s] (None: base_speed)
    pins_contact: torch.Tensor | None = None  # bool: pre-contact samples fitted (``CurveKinematics``; None: none)
    curve_inflation: torch.Tensor | None = None  # κ² of each sample's curve for the whiteness test (None: the set's)
    # The baseline line removed from each sample's curve, whose error a fit carries (``ptwin.fitting.baseline_line``):
    travel: torch.Tensor | None = None  # z from the estimated contact [m] (0 where no line was removed)
    line_sums: torch.Tensor | None = None  # (S, 3): (n, Σt, Σt²) of the line's samples (zeros: no line)
    own_level: torch.Tensor | None = None  # bool: the curve's own level was removed (not the set's common one)
    reference_line: tuple[float, float, float] | None = None  # the reference curve's line sums (the law's error)
    noise_gain: torch.Tensor | None = None  # 1 + s/k_s: the force noise's gain in the residual (None: 1)

    def __post_init__(self):
        if self.segment is None:
            self.segment = torch.zeros_like(self.curve)
        if self.nominal_speed is None:
            self.nominal_speed = self.base_speed
        if self.pins_contact is None:
            self.pins_contact = torch.zeros_like(self.in_contact)
        if self.curve_inflation is None:
            self.curve_inflation = torch.full_like(self.time, self.noise_inflation)
        if self.travel is None:
            self.travel = torch.zeros_like(self.time)
        if self.line_sums is None:
            self.line_sums = torch.zeros(self.time.numel(), 3, dtype=self.time.dtype, device=self.time.device)
        if self.own_level is None:
            self.own_level = torch.zeros_like(self.in_contact)
        if self.noise_gain is None:
            self.noise_gain = torch.ones_like(self.time)

    @property
    def fitted(self) -> torch.Tensor:
        """bool: the samples a fit may use: those in contact and those just before it (``pins_contact``)."""
        return self.in_contact | self.pins_contact

    def in_contact_by_curve(self, values: torch.Tensor) -> list[torch.Tensor]:
        """``values`` (one per sample) on each curve's samples in contact, in ``curve_ids`` order: the records a
        residual's correlation is read on."""
        return [values[(self.curve == i) & self.in_contact] for i in range(len(self.curve_ids))]

    @classmethod
    def from_curves(
        cls,
        curves: list[CurveKinematics],
        noise_inflation: float = 1.0,
        reference: CurveKinematics | None = None,
        noise_gain: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> Samples:
        """The curves' samples; ``noise_inflation``: the set's κ². A curve whose own baseline measured a
        larger κ² (real noise drifts more on some curves than on others) keeps its own for the whiteness
        test: the set's would read its correlated noise as structure. ``reference``: the reference curve, whose
        removed line the elastic law carries into every curve; its own samples carry none (the law read off its
        approach has the same error as its hold). ``noise_gain``: depth [m] → the force noise's gain in the residual
        there (``ReferenceCurve.noise_gain``; None: 1)."""

        def cat(values):
            return torch.from_numpy(np.concatenate(values))

        starts = [np.arange(len(c.time)) == 0 for c in curves]
        gains = [np.ones_like(c.depth) if noise_gain is None else noise_gain(c.depth) for c in curves]
        return cls(
            time=cat([c.time for c in curves]),
            depth=cat([c.depth for c in curves]),
            velocity=cat([c.velocity for c in curves]),
            base_speed=cat([c.base_speeds for c in curves]),
            force=cat([c.force for c in curves]),
            start=cat(starts),
            curve=cat([np.full(len(c.time), i) for i, c in enumerate(curves)]),
            in_contact=cat([c.in_contact for c in curves]),
            noise_floor=cat([c.noise_floor * gain for c, gain in zip(curves, gains)]),
            curve_ids=tuple(c.curve for c in curves),
            noise_inflation=noise_inflation,
            segment=cat([c.segment for c in curves]),
            nominal_speed=cat([np.full(len(c.time), c.base_speed) for c in curves]),
            pins_contact=cat([c.pins_contact for c in curves]),
            curve_inflation=cat([np.full(len(c.time), max(noise_inflation, c.noise.inflation)) for c in curves]),
            travel=cat([c.z if _line_sums(c, reference) else np.zeros_like(c.z) for c in curves]),
            line_sums=cat([np.tile(_line_sums(c, reference) or (0.0,) * 3, (len(c.time), 1)) for c in curves]),
            own_level=cat([np.full(len(c.time), c.baseline is not None and not c.baseline.common) for c in curves]),
            reference_line=None if reference is None else _line_sums(reference, None),
            noise_gain=cat(gains),
        )

    def join(self, other: Samples) -> Samples:
        """These samples followed by ``other``'s (its curves after these; the noise inflation is these')."""
        values = {}
        for f in fields(self):
            mine, theirs = getattr(self, f.name), getattr(other, f.name)
            if f.name == "curve":
                theirs = theirs + len(self.curve_ids)
            values[f.name] = torch.cat([mine, theirs]) if torch.is_tensor(mine) else mine
        values["curve_ids"] = self.curve_ids + other.curve_ids
        return Samples(**values)

    def curve_alone(self, curve: int) -> tuple[Samples, int]:
        """The samples of curve ``curve`` (an index into ``curve_ids``) as a set of that one curve, and where
        they start in these: a fit to one curve need not evaluate the others (a model's force on a curve
        depends on that curve's history and the reference curve alone)."""
        rows = torch.nonzero(self.curve == curve).squeeze(1)
        first = int(rows[0])
        part = slice(first, first + rows.numel())  # a curve's samples are contiguous (``from_curves``, ``join``)
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        values = {name: value[part] if torch.is_tensor(value) else value for name, value in values.items()}
        values["curve"] = torch.zeros_like(values["curve"])
        values["curve_ids"] = (self.curve_ids[curve],)
        return Samples(**values), first

    def __len__(self) -> int:
        return self.time.numel()

    def to(self, device: str | torch.device) -> Samples:
        moved = {f.name: getattr(self, f.name) for f in fields(self)}
        return Samples(**{k: v.to(device) if torch.is_tensor(v) else v for k, v in moved.items()})


def _line_sums(curve: CurveKinematics, reference: CurveKinematics | None) -> tuple[float, float, float] | None:
    """The sums of the baseline line removed from ``curve`` (``Baseline.line_sums``); None where none was, or
    ``curve`` is the ``reference``."""
    if curve.baseline is None or (reference is not None and curve.curve == reference.curve):
        return None
    return curve.baseline.line_sums
