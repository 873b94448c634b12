"""Hereditary terms as first-order linear recurrences, evaluated by a parallel scan.

x_i = a_i x_{i−1} + b_i over all samples at once: log₂(S) vectorised steps instead of
a Python loop per sample, so torch.func Jacobians of relaxation terms stay cheap.
"""

from __future__ import annotations

import torch


def linear_recurrence(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """x with x_i = a_i x_{i−1} + b_i and x_{−1} = 0 (set a_i = 0 to restart at i)."""
    n = a.numel()
    shift = 1
    while shift < n:
        a_before = torch.cat([torch.ones_like(a[:shift]), a[:-shift]])
        b_before = torch.cat([torch.zeros_like(b[:shift]), b[:-shift]])
        a, b = a * a_before, a * b_before + b
        shift *= 2
    return b


def _decay(time: torch.Tensor, start: torch.Tensor, relaxation_time: torch.Tensor):
    """(a, τ(1 − a)/Δt) per sample for a = exp(−Δt/τ); a = 0 where τ = 0 or a curve starts."""
    step = torch.diff(time, prepend=time[:1]).where(~start, torch.ones_like(time))
    positive = relaxation_time > 0
    safe_tau = relaxation_time.where(positive, torch.ones_like(relaxation_time))
    a = torch.exp(-step / safe_tau).where(positive & ~start, torch.zeros_like(time))
    return a, (safe_tau * (1 - a) / step).where(positive, torch.zeros_like(time))


def first_order_lag(
    forcing: torch.Tensor, relaxation_time: torch.Tensor, time: torch.Tensor, start: torch.Tensor
) -> torch.Tensor:
    """y with τ y' + y = u, exact for u linear between samples; y = u at each curve start.

    Args:
        forcing: u (S,); relaxation_time: τ ≥ 0 (S,) [s]; time: (S,) [s]; start: bool (S,).
    """
    a, weight = _decay(time, start, relaxation_time)
    previous = torch.cat([forcing[:1], forcing[:-1]])
    b = forcing - a * previous - (forcing - previous) * weight
    return linear_recurrence(a, b.where(~start, forcing))


def relaxation_integral(
    signal: torch.Tensor, relaxation_time: torch.Tensor, time: torch.Tensor, start: torch.Tensor
) -> torch.Tensor:
    """q(t) = ∫₀ᵗ exp(−(t−s)/τ) ds'(s) ds from each curve start, exact for s linear between samples."""
    a, weight = _decay(time, start, relaxation_time)
    increment = torch.diff(signal, prepend=signal[:1])
    return linear_recurrence(a, (increment * weight).where(~start, torch.zeros_like(signal)))
