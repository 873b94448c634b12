"""The elastic law under hereditary terms: F with A·F = target, A causal (``hereditary_inverse``), solved exactly.

The solve is block substitution, outside autograd (``_Substitution``). Its derivatives are the other solve's:
d(A⁻¹b) = A⁻¹(db − dA·A⁻¹b), so a cotangent ḡ pulls back to λ = A⁻ᵀḡ on ``target`` and to −⟨λ, dA·F⟩ on the
parameters, the operator's own derivative in closed form, O(samples × modes) (``_operator_slopes``). LM's
Jacobians differentiate that gradient again (``ptwin.fitting.lm.Traced``): λ is one more node of the same kind,
so a Jacobian walks a few substitutions and a small graph, not the graph of every block's solve three times."""

from __future__ import annotations

import functools

import torch

from ptwin.physics.node import Node
from ptwin.physics.recurrence import decay_slopes, decays, recurrence_pullback, relaxation_integral, step_mean

BLOCK_WORK = 1000  # block × modes of the substitution: one exponential's law in a block or two


def hereditary_inverse(
    target: torch.Tensor,
    extra: torch.Tensor,
    weights: torch.Tensor,
    times: torch.Tensor,
    time: torch.Tensor,
    block: int | None = None,
    kept: KeptGeometry | None = None,
) -> torch.Tensor:
    """F on one curve's samples [N] with A·F = F + extra·(F − F₀) + Σ_m weights_m·q_m = target, q_m the relaxation
    integral of F with τ_m = ``times`` (M,) [s] from the first sample (``relaxation_integral``).

    The operator is causal with a positive diagonal, so it is solved exactly by block forward substitution:
    ``block`` samples at a time (default: ``BLOCK_WORK`` / modes, at least 25), a dense lower-triangular
    system in the increments of F, the modes carried from block to block — where a fixed point
    F ← target − Σ(…) diverges once the memory outweighs F (g > 1, or a power law's weight on the last step).
    Differentiable in ``target``, ``extra``, ``weights`` and ``times``, to any order. ``kept``: where the caller
    solves again and again on the same samples, the geometry of the last solve, reused while its times are."""
    if block is None:  # a block's work grows as block² × modes and the loop's cost as samples / block
        block = max(BLOCK_WORK // max(times.numel(), 1), 25)
    geometry = _Geometry(times.detach(), time, block) if kept is None else kept.geometry(times.detach(), time, block)
    blocks = _Substitution(extra.detach(), weights.detach(), geometry)
    return _HereditarySolve.apply(target, extra, weights, times, time, blocks, False)


class _Geometry:
    """What A owes to the sample times and the modes' times alone, not to the weights: each block's decays
    across its samples and the kernel of its steps, and each mode's decay over each step (``decays``, what
    ``_operator_slopes`` differentiates). A power law's modes keep their times at every step of a fit (α moves
    their weights only): built once a fit, not once an evaluation, it took a fifth of a power-law fit's time."""

    def __init__(self, times: torch.Tensor, time: torch.Tensor, block: int):
        self.times, self.time, self.block, self.blocks = times, time, block, []
        for begin in range(1, time.numel(), block):
            end = min(begin + block, time.numel())
            since = time[begin:end, None] - time[None, begin - 1 : end]  # (B, B + 1): t_i − t_k, k from begin − 1
            decay = torch.exp(-since.clamp(min=0)[..., None] / times)  # (B, B + 1, M)
            kernel = decay[:, 1:] * step_mean(torch.diff(time[begin - 1 : end])[:, None] / times)
            # from the sample before the block to each of its samples, across the block, and from each to its last
            self.blocks.append((begin, end, decay[:, 0], decay[-1, 0], kernel[-1], kernel))

    @functools.cached_property
    def decayed(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(M, N): a = exp(−Δt/τ) and the step's mean of exp(−s/τ); asked for where the times need no gradient."""
        start = torch.arange(self.time.numel(), device=self.time.device) == 0
        return decays(self.time, start, self.times[:, None])


class KeptGeometry:
    """The last ``_Geometry`` built, given again while the sample times are the same tensor, unwritten, and
    the modes' times equal."""

    def __init__(self):
        self._last: tuple[int, _Geometry] | None = None

    def geometry(self, times: torch.Tensor, time: torch.Tensor, block: int) -> _Geometry:
        last = self._last
        if not (
            last is not None
            and last[1].time is time
            and last[0] == time._version
            and last[1].block == block
            and torch.equal(last[1].times, times)
        ):
            last = self._last = (time._version, _Geometry(times, time, block))
        return last[1]


class _Substitution:
    """A's blocks for given parameters, kept for every solve a Jacobian asks of them (one forward, one adjoint,
    one forward a column).

    Written in the increments ΔF_k = F_k − F_{k−1}, A·F = F₀ + T·ΔF on each sample after the first, T lower
    triangular with T[i, k] = 1 + extra + Σ_m w_m exp(−(t_i − t_k)/τ_m) mean_{k,m}, mean_{k,m} the mean of
    exp(−s/τ_m) over step k. Each block holds its diagonal piece of T and the decays that carry the modes
    across its edges (``_Geometry``)."""

    def __init__(self, extra: torch.Tensor, weights: torch.Tensor, geometry: _Geometry):
        self.extra, self.weights, self.geometry = extra, weights, geometry
        self.blocks = [
            (begin, end, entering, across, leaving, (kernel @ weights + (1 + extra)).tril())
            for begin, end, entering, across, leaving, kernel in geometry.blocks
        ]

    def solve(self, target: torch.Tensor) -> torch.Tensor:
        """F = A⁻¹·target, the blocks in turn; the modes Σ_k exp(−(t − t_k)/τ_m) mean_{k,m} ΔF_k carried."""
        first = target[0]
        values, modes = [first[None]], torch.zeros_like(self.weights)
        for begin, end, entering, across, leaving, system in self.blocks:
            previous = values[-1][-1]
            carried = entering @ (self.weights * modes)
            rhs = target[begin:end] - carried - previous + self.extra * (first - previous)
            increments = torch.linalg.solve_triangular(system, rhs[:, None], upper=False)[:, 0]
            values.append(previous + torch.cumsum(increments, 0))
            modes = across * modes + leaving.T @ increments
        return torch.cat(values)

    def solve_transposed(self, cotangent: torch.Tensor) -> torch.Tensor:
        """λ = A⁻ᵀ·cotangent: Tᵀλ_{≥1} = the cotangent's sums from each sample on, the blocks from the last, the
        later samples' pull carried back as modes Σ_i λ_i exp(−(t_i − t)/τ_m); λ₀ what the first sample keeps."""
        suffix = cotangent.flip(0).cumsum(0).flip(0)
        pieces, tail, modes = [], cotangent.new_zeros(()), torch.zeros_like(self.weights)
        for begin, end, entering, across, leaving, system in reversed(self.blocks):
            later = (1 + self.extra) * tail + leaving @ (self.weights * modes)
            dual = torch.linalg.solve_triangular(system.mT, (suffix[begin:end] - later)[:, None], upper=True)[:, 0]
            pieces.append(dual)
            tail = tail + dual.sum()
            modes = across * modes + entering.T @ dual
        return torch.cat([(cotangent.sum() - tail)[None], *reversed(pieces)])


class _HereditarySolve(Node):
    """x = A⁻¹b, or A⁻ᵀb (``transposed``), by the blocks of ``_Substitution``. ⟨ḡ, dx⟩ = ⟨λ, db⟩ − ⟨λ, dA·x⟩
    with λ = A⁻ᵀḡ (transposed: ⟨λ, db⟩ − ⟨x, dA·λ⟩, λ = A⁻¹ḡ); λ is this node again, the other way, so a
    gradient's gradient is as exact as the gradient."""

    @staticmethod
    def forward(b, extra, weights, times, time, blocks, transposed):
        return blocks.solve_transposed(b) if transposed else blocks.solve(b)

    @staticmethod
    def setup_context(ctx, inputs, output):
        _, extra, weights, times, time, blocks, transposed = inputs
        ctx.save_for_backward(extra, weights, times, time, output)
        ctx.blocks, ctx.transposed = blocks, transposed

    @staticmethod
    def backward(ctx, grad):
        extra, weights, times, time, solution = ctx.saved_tensors
        dual = _HereditarySolve.apply(grad, extra, weights, times, time, ctx.blocks, not ctx.transposed)
        needs = ctx.needs_input_grad[1:4]
        if not any(needs):
            return dual, None, None, None, None, None, None
        left, right = (solution, dual) if ctx.transposed else (dual, solution)
        slopes = _operator_slopes(left, right, weights, times, ctx.blocks.geometry, needs[2])
        return dual, *(-g if need else None for g, need in zip(slopes, needs)), None, None, None


def _operator_slopes(
    left: torch.Tensor,
    right: torch.Tensor,
    weights: torch.Tensor,
    times: torch.Tensor,
    geometry: _Geometry,
    to_times: bool,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
    """∂⟨left, A·right⟩/∂(extra, weights, times), left and right held, in closed form; the last only where
    ``to_times`` (a power law's modes keep their times: nothing asks for it).

    Plain torch ops and the recurrence's node, so the result differentiates again in all five; an autograd call
    here would also run on through the nodes that made ``left`` and ``right`` (this one among them). The modes'
    decays are the geometry's where nothing differentiates them (their times need no gradient); the sample times
    are the geometry's."""
    time = geometry.time
    start = torch.arange(time.numel(), device=time.device) == 0
    tau = times[:, None]
    decayed = decays(time, start, tau) if times.requires_grad else geometry.decayed
    memory = relaxation_integral(right, tau, time, start, decayed)  # q_m of right
    extra_slope, weights_slope = torch.dot(left, right - right[0]), memory @ left
    if not to_times:
        return extra_slope, weights_slope, None
    to_decay, to_forcing = recurrence_pullback(decayed[0], memory, left.expand_as(memory))
    decay_slope, mean_slope = decay_slopes(time, start, tau, decayed)
    increment = torch.diff(right, prepend=right[:1])  # the forcing is increment × mean (0 at the start)
    times_slope = weights * (to_decay * decay_slope + to_forcing * increment * mean_slope).sum(-1)
    return extra_slope, weights_slope, times_slope
