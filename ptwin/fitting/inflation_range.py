"""The range of the noise's κ² over which the decisions made on the way to a set of fits go the same way.

A fit's optimum never reads κ² (LM works in units of the noise std σ), but a few decisions on the way to it do:
whether the reference's contact correction is freed (its standard error scales with κ), whether a held one moves
later (its gain is weighed under the noise model), whether a term's effect is below the noise. Each narrows the
range being ``recorded``; for any κ² inside it the same fits would be made again, to the last bit, and only what
they say under the noise model changes (``PhysicsFit.under``). The pipeline reads the noise's correlation up to
three times (``ptwin.pipeline.run.diagnose_set``: off the hybrid twin's residual, capped by the first fits' residuals,
then by those of the subsets weighed) and so fits again only where a later reading lies outside the range of the
fits made so far.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass


@dataclass
class InflationRange:
    """An open interval of κ² (dimensionless)."""

    low: float = 0.0
    high: float = math.inf

    def holds(self, inflation: float) -> bool:
        return self.low < inflation < self.high

    def narrow(self, low: float, high: float) -> None:
        self.low, self.high = max(self.low, low), min(self.high, high)

    def __and__(self, other: InflationRange) -> InflationRange:
        return InflationRange(max(self.low, other.low), min(self.high, other.high))


_RECORDING: ContextVar[InflationRange | None] = ContextVar("inflation_range", default=None)


@contextmanager
def recorded() -> Iterator[InflationRange]:
    """The range of κ² within which every decision made inside the ``with`` block goes the way it went."""
    span = InflationRange()
    token = _RECORDING.set(span)
    try:
        yield span
    finally:
        _RECORDING.reset(token)


def decided(inflation: float, threshold: float, below: bool) -> None:
    """Record a decision made at κ² ``inflation`` that goes one way for κ² below ``threshold`` and the other above
    it (``below``: the side it went, as the decision's own arithmetic found it). A threshold that is not a positive
    number decides nothing; a decision whose side disagrees with ``inflation < threshold`` (they meet to the last
    bit) leaves no range."""
    span = _RECORDING.get()
    if span is None or not 0.0 < threshold < math.inf:
        return
    if below != (inflation < threshold):
        span.narrow(inflation, inflation)
    elif below:
        span.narrow(0.0, threshold)
    else:
        span.narrow(threshold, math.inf)
