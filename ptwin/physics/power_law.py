"""Ting's hereditary integral for a power-law relaxation modulus, in O(N) per curve.

The kernel k(τ) = (τ/t0)^(−α), t0 = 1 s, is a superposition of exponentials — its Laplace
representation τ^(−α) = (1/Γ(α)) ∫₀^∞ s^(α−1) e^(−sτ) ds, written in u = ln s:
(1/Γ(α)) ∫ e^(αu) e^(−e^u τ) du. A midpoint rule on a uniform grid of u (``PER_EFOLD``
nodes per e-fold) converges exponentially on this analytic, doubly-exponentially decaying
integrand; the rates run from ``SLOW_MARGIN`` below 1/longest to ``FAST_MARGIN`` above
1/shortest (the time scales of the data), and the slow tail below the grid, for which
e^(−sτ) ≈ 1, is a constant c0 = e^(α·u_low)/Γ(1 + α) (what limits the accuracy at the
longest times, hence the wider slow margin). So

    k(τ) ≈ c0 + Σ_j c_j e^(−τ/τ_j),   c_j = h·α·e^(α u_j)/Γ(1 + α),  τ_j = e^(−u_j),

(1/Γ(α) written as α/Γ(1 + α): smooth through α = 0, where k = 1 exactly), and Ting's
integral ∫₀ᵗ k(t − s) dF/ds ds is c0·(F − F(0)) plus one relaxation recurrence per mode
(``ptwin.physics.recurrence``), exact for F linear between samples. Accuracy of the
kernel (tests/test_power_law.py): relative error ≤ 1e-4 over [shortest, longest] for
0 ≤ α < 0.5; 49 modes for time scales from 0.1 ms to 10 s, 56 from 0.1 ms to 1000 s.
"""

from __future__ import annotations

import math

import torch

from ptwin.physics.recurrence import decays, relaxation_integral

T0 = 1.0  # [s]: E* is the modulus at t0
PER_EFOLD = 1.5
SLOW_MARGIN, FAST_MARGIN = 1e5, 1e4


def kernel_modes(alpha: torch.Tensor, shortest: float, longest: float):
    """(c0, weights c_j (M,), relaxation times τ_j [s] (M,)) of k(τ) = (τ/t0)^(−α) for τ in
    [``shortest``, ``longest``] [s]; ``alpha`` a 0-d tensor (differentiable)."""
    low = math.log(T0 / (SLOW_MARGIN * longest))
    high = math.log(FAST_MARGIN * T0 / shortest)
    count = int(math.ceil((high - low) * PER_EFOLD))
    step = (high - low) / count
    u = low + step * (torch.arange(count, dtype=torch.float64, device=alpha.device) + 0.5)
    scale = torch.exp(-torch.lgamma(1.0 + alpha))
    weights = step * alpha * torch.exp(alpha * u) * scale
    return torch.exp(alpha * low) * scale, weights, T0 * torch.exp(-u)


def kernel_for(alpha: torch.Tensor, time: torch.Tensor):
    """``kernel_modes`` over the time scales of samples at ``time`` [s]: their shortest step to their span."""
    steps = torch.diff(time)
    steps = steps[steps > 0]
    shortest = float(steps.min()) if steps.numel() else 1e-3
    longest = float(time.max() - time.min()) or 1.0
    return kernel_modes(alpha, shortest, max(longest, shortest))


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
    _, _, times = kernel_for(torch.zeros((), dtype=time.dtype, device=time.device), time)
    return decays(time, start, times[:, None])


def linear_origin(signal: torch.Tensor, start: torch.Tensor) -> torch.Tensor:
    """F(0) of each sample's curve: the signal at its curve's first sample."""
    curve = torch.cumsum(start.long(), dim=0) - 1
    return signal[start][curve]
