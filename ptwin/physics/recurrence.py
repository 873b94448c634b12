"""Hereditary terms as first-order linear recurrences, x_i = a_i x_{i−1} + b_i over all samples at once.

The recurrence is one autograd node whose derivatives are recurrences too (``_LinearRecurrence``):
autograd through a scan's log₂(S) slices allocated and summed a full-size gradient for every slice,
60% of a power-law fit's Jacobian on the bench map's spots. On the CPU it is solved by LAPACK's banded
triangular substitution (``_substituted``), O(S) work a recurrence in compiled code; elsewhere (a GPU) by a
parallel scan (``_parallel_scan``), log₂(S) vectorised steps of O(S) work each.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
import torch

from ptwin.physics.node import Node


def linear_recurrence(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """x with x_i = a_i x_{i−1} + b_i and x_{−1} = 0 along the last dimension (set a_i = 0 to restart
    at i); leading dimensions are independent recurrences (e.g. the modes of a kernel)."""
    a, b = torch.broadcast_tensors(a, b)
    return _LinearRecurrence.apply(a, b, False)


def _scan(a: torch.Tensor, b: torch.Tensor, reverse: bool) -> torch.Tensor:
    """The recurrence's values, forwards or, ``reverse``, from the last sample back (x_i = a_i x_{i+1} + b_i);
    outside autograd."""
    if a.device.type == "cpu" and a.numel():
        return _substituted(a, b, reverse)
    return _parallel_scan(a, b, reverse)


# LAPACK's float64 banded triangular solve, looked up once: a lookup per call was a tenth of a solve's time.
_BANDED_TRIANGULAR = scipy.linalg.get_lapack_funcs("tbtrs", (np.empty(0),))


def _substituted(a: torch.Tensor, b: torch.Tensor, reverse: bool) -> torch.Tensor:
    """``_scan`` by substitution: the recurrence is the unit bidiagonal system x_i − a_i x_{i−1} = b_i, lower
    (upper, ``reverse``). The recurrences of the leading dimensions are laid end to end with no coupling between
    one's last sample and the next one's first, so one LAPACK call (``tbtrs``) solves them all, each as
    x_i = b_i + a_i x_{i−1} in turn. 2 ms for the 43 modes × 8000 samples of a power law on the demo,
    against the parallel scan's 15 ms."""
    band = torch.empty(*a.shape, 2, dtype=a.dtype)  # LAPACK's band storage, column-major; the unit diagonal unread
    if reverse:  # row 0: A[j−1, j] = −a_{j−1}
        torch.neg(a[..., :-1], out=band[..., 1:, 0])
        band[..., 0, 0] = 0.0
    else:  # row 1: A[j+1, j] = −a_{j+1}
        torch.neg(a[..., 1:], out=band[..., :-1, 1])
        band[..., -1, 1] = 0.0
    storage = band.reshape(-1, 2).numpy().T
    solve = _BANDED_TRIANGULAR if storage.dtype == np.float64 else scipy.linalg.get_lapack_funcs("tbtrs", (storage,))
    x, info = solve(storage, b.detach().reshape(-1, 1).numpy(), uplo="U" if reverse else "L", diag="U")
    if info != 0:
        raise ValueError(f"LAPACK's tbtrs refused the recurrence (info {info})")
    return torch.from_numpy(x).reshape(b.shape)


def _parallel_scan(a: torch.Tensor, b: torch.Tensor, reverse: bool) -> torch.Tensor:
    """``_scan`` by a parallel (Hillis–Steele) scan, in place on copies."""
    a, b = a.clone(), b.clone()
    n, shift = a.shape[-1], 1
    while shift < n:
        # each sample takes in the partial sum ``shift`` samples before it (after it, in reverse)
        to, of = (slice(None, -shift), slice(shift, None)) if reverse else (slice(shift, None), slice(None, -shift))
        b[..., to] += a[..., to] * b[..., of]
        if 2 * shift < n:  # the last level's products are never read
            a[..., to] = a[..., to] * a[..., of]
        shift *= 2
    return b


class _LinearRecurrence(Node):
    """x = R(a, b), forwards or ``reverse``. Its derivatives are recurrences again: the adjoint runs the other
    way, g_i = ḡ_i + a_{i+1} g_{i+1}, with ∂/∂b = g and ∂/∂a_i = g_i x_{i−1}; the tangent is R(a, ȧ·x_{i−1} +
    ḃ). Both call this node, so gradients of gradients (``ptwin.fitting.lm.Traced``) and forward AD work."""

    @staticmethod
    def forward(a, b, reverse):
        return _scan(a, b, reverse)

    @staticmethod
    def setup_context(ctx, inputs, output):
        a, _, reverse = inputs
        ctx.reverse = reverse
        ctx.save_for_backward(a, output)
        ctx.save_for_forward(a, output)

    @staticmethod
    def backward(ctx, grad):
        a, x = ctx.saved_tensors
        return *_pullback(a, x, grad, ctx.reverse, ctx.needs_input_grad[0]), None

    @staticmethod
    def jvp(ctx, a_tangent, b_tangent, _):
        a, x = ctx.saved_tensors
        tangent = torch.zeros_like(x) if b_tangent is None else b_tangent
        if a_tangent is not None:
            tangent = tangent + a_tangent * _shifted(x, ctx.reverse)
        return _LinearRecurrence.apply(a, tangent, ctx.reverse)

    @staticmethod
    def vmap(info, in_dims, a, b, reverse):
        # Leading dimensions are independent recurrences already: a batch is one more (torch.func's jacfwd
        # batches the tangents). A generated rule would run the forward on batched tensors LAPACK cannot read.
        a, b = (x.expand(info.batch_size, *x.shape) if d is None else x.movedim(d, 0) for x, d in zip((a, b), in_dims))
        a, b = torch.broadcast_tensors(a, b)
        return _LinearRecurrence.apply(a, b, reverse), 0


def recurrence_pullback(a: torch.Tensor, x: torch.Tensor, cotangent: torch.Tensor):
    """(ā, b̄) with ⟨cotangent, dx⟩ = ⟨ā, da⟩ + ⟨b̄, db⟩ for x = ``linear_recurrence``(a, b); differentiable again."""
    return _pullback(a, x, cotangent, False, True)


def _pullback(a: torch.Tensor, x: torch.Tensor, cotangent: torch.Tensor, reverse: bool, to_a: bool):
    """``recurrence_pullback`` of the recurrence run either way (ā only where ``to_a``): the adjoint g_i = ḡ_i +
    a_{i+1} g_{i+1} runs the other way, b̄ = g and ā_i = g_i x_{i−1}."""
    adjoint = _LinearRecurrence.apply(_shifted(a, not reverse), cotangent, not reverse)
    return (adjoint * _shifted(x, reverse) if to_a else None), adjoint


def _shifted(x: torch.Tensor, later: bool) -> torch.Tensor:
    """x_{i−1} at i (``later``: x_{i+1}), zero past the end."""
    zero = torch.zeros_like(x[..., :1])
    return torch.cat([zero, x[..., :-1]], dim=-1) if not later else torch.cat([x[..., 1:], zero], dim=-1)


def decays(time: torch.Tensor, start: torch.Tensor, relaxation_time: torch.Tensor):
    """(a, τ(1 − a)/Δt) per sample for a = exp(−Δt/τ); a = 0 where τ = 0 or a curve starts; the mean
    τ(1 − a)/Δt → 1 over a step of zero length (repeated times)."""
    step, positive, safe_tau = _steps(time, start, relaxation_time)
    a = torch.exp(-step / safe_tau).where(positive & ~start, torch.zeros_like(time))
    return a, step_mean(step / safe_tau).where(positive, torch.zeros_like(time))


def decay_slopes(
    time: torch.Tensor, start: torch.Tensor, relaxation_time: torch.Tensor, decayed: tuple[torch.Tensor, torch.Tensor]
):
    """∂/∂τ of ``decays``' (a, mean) [1/s], ``decayed`` their values: a·Δt/τ² and (mean − exp(−Δt/τ))/τ, 0 where
    τ = 0 (a's also at a curve's start, the mean's over a step of zero length)."""
    a, mean = decayed
    step, positive, safe_tau = _steps(time, start, relaxation_time)
    ratio = step / safe_tau
    return a * ratio / safe_tau, (mean - torch.exp(-ratio)).where(positive, torch.zeros_like(mean)) / safe_tau


def _steps(time: torch.Tensor, start: torch.Tensor, relaxation_time: torch.Tensor):
    """(Δt per sample, 1 at a curve's start; τ > 0; τ, 1 where it is not)."""
    step = torch.diff(time, prepend=time[:1]).where(~start, torch.ones_like(time))
    positive = relaxation_time > 0
    return step, positive, relaxation_time.where(positive, torch.ones_like(relaxation_time))


def step_mean(ratio: torch.Tensor) -> torch.Tensor:
    """(1 − exp(−x))/x, the mean of exp(−s/τ) over a step of x = Δt/τ, and 1 at x = 0."""
    moving = ratio > 0
    safe = ratio.where(moving, torch.ones_like(ratio))
    return (-torch.expm1(-safe) / safe).where(moving, torch.ones_like(ratio))


def first_order_lag(
    forcing: torch.Tensor, relaxation_time: torch.Tensor, time: torch.Tensor, start: torch.Tensor
) -> torch.Tensor:
    """y with τ y' + y = u, exact for u linear between samples; y = u at each curve start.

    Args:
        forcing: u (S,); relaxation_time: τ ≥ 0 (S,) [s]; time: (S,) [s]; start: bool (S,).
    """
    a, weight = decays(time, start, relaxation_time)
    previous = torch.cat([forcing[:1], forcing[:-1]])
    b = forcing - a * previous - (forcing - previous) * weight
    return linear_recurrence(a, b.where(~start, forcing))


def relaxation_integral(
    signal: torch.Tensor,
    relaxation_time: torch.Tensor,
    time: torch.Tensor,
    start: torch.Tensor,
    decayed: tuple[torch.Tensor, torch.Tensor] | None = None,
) -> torch.Tensor:
    """q(t) = ∫₀ᵗ exp(−(t−s)/τ) ds'(s) ds from each curve start, exact for s linear between samples.

    ``relaxation_time`` τ: (S,), or (M, 1) for M modes at once (result (M, S)); ``decayed``: its ``decays``,
    where the caller keeps them (they depend on the times alone)."""
    a, weight = decays(time, start, relaxation_time) if decayed is None else decayed
    increment = torch.diff(signal, prepend=signal[:1])
    return linear_recurrence(a, (increment * weight).where(~start, torch.zeros_like(signal)))
