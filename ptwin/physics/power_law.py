"""Ting's hereditary integral for a power-law relaxation modulus, in O(N) per curve.

The kernel k(τ) = (τ/t0)^(−α), t0 = 1 s, is a superposition of exponentials — its Laplace
representation τ^(−α) = (1/Γ(α)) ∫₀^∞ s^(α−1) e^(−sτ) ds, written in u = ln s:
(1/Γ(α)) ∫ e^(αu) e^(−e^u τ) du. A midpoint rule on a uniform grid of u (``PER_EFOLD``
nodes per e-fold) converges exponentially on this analytic, doubly-exponentially decaying
integrand; the rates run from ``SLOW_MARGIN`` below 1/longest to ``FAST_MARGIN`` above
1/shortest (the time scales of the data). The slow tail below the grid, for which
e^(−sτ) ≈ 1, is a constant c0 = e^(α·u_low)/Γ(1 + α) (what limits the accuracy at the
longest times, hence the wider slow margin). The fast tail above the grid relaxes within a
hundredth of the shortest step: over any step it acts through its mass ∫ k alone, the kernel's
singular part near τ = 0, so one mode at the grid's edge carries that mass in closed form,
m = α·e^((α−1)·u_high)/((1 − α)·Γ(1 + α)) (t0 = 1 s). Truncated instead, its mass was missing from
the latest step of every integral: 2.6e-4 of the force at α = 0.45 with the margin at 1e4, where it
is 2e-5 with this mode at 100. So

    k(τ) ≈ c0 + Σ_j c_j e^(−τ/τ_j),   c_j = h·α·e^(α u_j)/Γ(1 + α),  τ_j = e^(−u_j),

(1/Γ(α) written as α/Γ(1 + α): smooth through α = 0, where k = 1 exactly), the fast tail's mode
last, and Ting's integral ∫₀ᵗ k(t − s) dF/ds ds is c0·(F − F(0)) plus one relaxation recurrence
per mode (``ptwin.physics.recurrence``), exact for F linear between samples. Accuracy
(tests/test_power_law.py): the kernel within 1e-4 over [shortest, longest] for 0 ≤ α < 0.5,
Ting's integral within 5e-5 of direct quadrature; 43 modes for time scales from 0.1 ms to 10 s
(49 with the tail truncated at a margin of 1e4), 50 from 0.1 ms to 1000 s.
"""

from __future__ import annotations

import math

import torch

from ptwin.physics.recurrence import decays, relaxation_integral

T0 = 1.0  # [s]: E* is the modulus at t0
PER_EFOLD = 1.5
SLOW_MARGIN, FAST_MARGIN = 1e5, 100


def _log_rates(shortest: float, longest: float, device=None) -> tuple[float, float, float, torch.Tensor]:
    """The grid of u = ln(rate·t0) for time scales in [``shortest``, ``longest``] [s]: (u_low, u_high, the
    grid's step h, its midpoints u_j)."""
    low = math.log(T0 / (SLOW_MARGIN * longest))
    high = math.log(FAST_MARGIN * T0 / shortest)
    count = int(math.ceil((high - low) * PER_EFOLD))
    step = (high - low) / count
    return low, high, step, low + step * (torch.arange(count, dtype=torch.float64, device=device) + 0.5)


def relaxation_times(shortest: float, longest: float, device=None) -> torch.Tensor:
    """τ_j [s] (M,) of ``kernel_modes``: they depend on the time scales alone, not on α."""
    _, high, _, u = _log_rates(shortest, longest, device)
    return _times(u, high)


def _times(u: torch.Tensor, high: float) -> torch.Tensor:
    """τ_j = t0·e^(−u_j) [s] of the grid's midpoints ``u``, then the fast tail's mode at its edge ``high``."""
    return T0 * torch.exp(-torch.cat([u, u.new_tensor([high])]))


def kernel_modes(alpha: torch.Tensor, shortest: float, longest: float):
    """(c0, weights c_j (M,), relaxation times τ_j [s] (M,)) of k(τ) = (τ/t0)^(−α) for τ in
    [``shortest``, ``longest``] [s], the last mode the fast tail's mass; ``alpha`` a 0-d tensor
    (differentiable)."""
    low, high, step, u = _log_rates(shortest, longest, alpha.device)
    scale = torch.exp(-torch.lgamma(1.0 + alpha))
    weights = step * alpha * torch.exp(alpha * u) * scale
    # The fast tail's mass m as a mode of τ = e^(−u_high): weight m/τ.
    # No finite mass where α ≥ 1 (the kernel is not integrable at τ = 0): an infinite weight, a force no fit accepts.
    tail = alpha * torch.exp(alpha * high) * scale / (1.0 - alpha).clamp(min=0.0)
    return torch.exp(alpha * low) * scale, torch.cat([weights, tail[None]]), _times(u, high)


def time_scales(time: torch.Tensor) -> tuple[float, float]:
    """(shortest, longest) [s] of samples at ``time``: their shortest step and their span."""
    steps = torch.diff(time)
    steps = steps[steps > 0]
    shortest = float(steps.min()) if steps.numel() else 1e-3
    longest = float(time.max() - time.min()) or 1.0
    return shortest, max(longest, shortest)


def kernel_for(alpha: torch.Tensor, time: torch.Tensor):
    """``kernel_modes`` over the time scales of samples at ``time`` [s]."""
    return kernel_modes(alpha, *time_scales(time))


def ting_integral(
    signal: torch.Tensor,
    alpha: torch.Tensor,
    time: torch.Tensor,
    start: torch.Tensor,
    decayed: tuple[torch.Tensor, torch.Tensor] | None = None,
) -> torch.Tensor:
    """F(0) + ∫₀ᵗ ((t − s)/t0)^(−α) dF/ds ds for F = ``signal`` (S,) on each curve (``start`` marks their
    first samples), exact for F linear between samples up to the kernel's accuracy. F(0), the value before
    contact, passes unrelaxed: an elastic law read off a noisy curve need not vanish at w = 0, and that
    offset is no stress in the network (dropping it shifted every curve by it). ``decayed``: the kernel's
    ``kernel_decays`` on these samples, where the caller keeps them."""
    c0, weights, times = kernel_for(alpha, time)
    origin = linear_origin(signal, start)
    modes = relaxation_integral(signal, times[:, None], time, start, decayed)
    return origin + c0 * (signal - origin) + weights @ modes


def kernel_decays(time: torch.Tensor, start: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Each mode's decay over each sample step (``ptwin.physics.recurrence.decays``). The modes' relaxation
    times depend on the samples' time scales, not on α: a fit that evaluates the same samples again and
    again needs them once (a quarter of the term's evaluation on the demo)."""
    return decays(time, start, relaxation_times(*time_scales(time), time.device)[:, None])


def linear_origin(signal: torch.Tensor, start: torch.Tensor) -> torch.Tensor:
    """F(0) of each sample's curve: the signal at its curve's first sample."""
    curve = torch.cumsum(start.long(), dim=0) - 1
    return signal[start][curve]
