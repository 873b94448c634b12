"""Greedy rank-one PGD enrichment with an alternating-directions fixed point.

Solves Σ_t ⊗_d A_t^d u = ⊗_d f^d for u = Σ_i α_i ⊗_d F_i^d. Every factor F_i^d is
kept at unit norm and its scale in α_i: products over six dimensions otherwise span
1e-100. After each new mode every dimension gets a Galerkin update over all modes at once
(cheap: one matrix pencil decouples it into one diagonal or banded solve per mode),
which is what lets greedy PGD converge in few modes.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import torch

from ptwin.pgd.config import EnrichmentSettings
from ptwin.pgd.dimensions import BandedDimension, DiagonalDimension

Dimension = DiagonalDimension | BandedDimension


@dataclass
class SeparatedSolution:
    """u = Σ_i amplitudes[i] ⊗_d factors[d][:, i], unit-norm factors."""

    names: list[str]
    factors: list[torch.Tensor]
    amplitudes: torch.Tensor
    history: list[dict] = field(default_factory=list)

    @property
    def modes(self) -> int:
        return self.amplitudes.numel()


def enrich(
    dims: list[Dimension],
    n_terms: int,
    settings: EnrichmentSettings,
    progress: Callable[[str], None] = print,
    output: Callable[[list[torch.Tensor], torch.Tensor], torch.Tensor] | None = None,
) -> SeparatedSolution:
    """Build the separated solution mode by mode; one progress line per mode.

    Stops when two modes in a row have a relative amplitude below ``amplitude_tol`` or
    change the quantity of interest, ``output(factors, amplitudes)`` (e.g. the force at
    probe points), by less than ``output_tol`` relative: the output residual.
    """
    generator = torch.Generator().manual_seed(settings.seed)
    capacity = settings.max_modes
    # Preallocated to the mode budget, one row per mode so that the first n modes are
    # contiguous: factors (capacity, N_d), applied A_t F (capacity, T, N_d).
    rows = [torch.zeros(capacity, dim.size, dtype=torch.float64) for dim in dims]
    applied_rows = [torch.zeros(capacity, n_terms, dim.size, dtype=torch.float64) for dim in dims]
    amplitudes = torch.zeros(capacity, dtype=torch.float64)
    history: list[dict] = []
    start = time.perf_counter()
    small_in_a_row = 0
    previous_output = None
    for mode in range(capacity):
        count = mode + 1
        known = ([a[:mode].reshape(-1, a.shape[2]) for a in applied_rows], amplitudes[:mode])
        new, amplitude, iterations = _new_mode(dims, n_terms, *known, settings, generator)
        for d, dim in enumerate(dims):
            rows[d][mode] = new[d]
            applied_rows[d][mode] = dim.apply(new[d][:, None])[:, :, 0]
        amplitudes[mode] = amplitude
        # Column views (N_d, n) and (T, N_d, n) of the same storage: updates write through.
        factors = [r[:count].T for r in rows]
        applied = [a[:count].permute(1, 2, 0) for a in applied_rows]
        amplitudes[:count] = _update_dimensions(dims, factors, applied, amplitudes[:count])
        relative_amplitude = float(amplitude.abs() / amplitudes[:count].abs().max())
        change = 1.0
        if output is not None:
            value = output(factors, amplitudes[:count])
            if previous_output is not None:
                change = float(((value - previous_output) / value).abs().max())
            previous_output = value
        entry = {
            "mode": count,
            "relative_amplitude": relative_amplitude,
            "output_change": change,
            "iterations": iterations,
            "seconds": time.perf_counter() - start,
        }
        history.append(entry)
        progress(
            f"mode {count:4d}  amplitude {relative_amplitude:.2e}  output change {change:.2e}"
            f"  fixed-point its {iterations:2d}  {entry['seconds']:6.2f} s"
        )
        converged = relative_amplitude < settings.amplitude_tol or change < settings.output_tol
        small_in_a_row = small_in_a_row + 1 if converged else 0
        if small_in_a_row >= 2:
            break
    progress(f"stopped after {len(history)} modes, last output change {history[-1]['output_change']:.2e}")
    count = len(history)
    return SeparatedSolution(
        [dim.name for dim in dims], [r[:count].T.contiguous() for r in rows], amplitudes[:count].clone(), history
    )


def _others(n_dims: int) -> list[list[int]]:
    """For each dimension d, the indices of every other dimension."""
    return [[e for e in range(n_dims) if e != d] for d in range(n_dims)]


def _product(values: list[torch.Tensor], dimensions, axis: int) -> torch.Tensor:
    """The elementwise product of ``values[d]`` over ``dimensions``, stacked along ``axis`` and reduced there."""
    return torch.stack([values[e] for e in dimensions], dim=axis).prod(dim=axis)


def _new_mode(dims, n_terms, applied, amplitudes, settings, generator):
    """Alternating-directions fixed point for the next rank-one correction.

    ``applied[d]`` (n·T, N_d) holds A_t^d F_i^d for the n known modes, mode-major.

    The projections are kept one tensor per dimension and stacked where a product over the other dimensions
    needs them: the same values in the same layout as columns of one tensor, so the same products to the bit,
    without a write into a column and a gather of columns per dimension and iteration (a fifth of a basis build,
    whose every op is small).
    """
    n_dims = len(dims)
    others = _others(n_dims)
    new = []
    for dim in dims:
        start = dim.load + 0.5 * dim.load.abs().max() * torch.rand(dim.size, generator=generator, dtype=torch.float64)
        new.append(start / start.norm())
    own = [None] * n_dims  # F_d^T A_t^d F_d (T,)
    loads = [None] * n_dims  # F_d^T f^d ()
    prior = [None] * n_dims  # F_d^T A_t^d F_i^d (T, n)

    def project(d):
        own[d] = dims[d].apply(new[d][:, None])[:, :, 0] @ new[d]
        prior[d] = (applied[d] @ new[d]).reshape(-1, n_terms).T
        loads[d] = new[d] @ dims[d].load

    for d in range(n_dims):
        project(d)
    for iteration in range(1, settings.max_fixed_point_iterations + 1):  # noqa: B007 (returned)
        previous = list(new)  # each factor is replaced, never written into
        for d in range(n_dims):
            coefficients = _product(own, others[d], 1)
            weights = amplitudes * _product(prior, others[d], 1)  # (T, n)
            rhs = _product(loads, others[d], 0) * dims[d].load - weights.T.reshape(-1) @ applied[d]
            solution = dims[d].solve(coefficients, rhs)
            new[d] = solution / torch.linalg.vector_norm(solution)
            project(d)
        overlap = torch.stack([f @ g for f, g in zip(new, previous)]).prod().abs()
        if 1.0 - overlap < settings.fixed_point_tol:
            break
    every = range(n_dims)
    stiffness = _product(own, every, 1).sum()
    amplitude = (_product(loads, every, 0) - (amplitudes * _product(prior, every, 1)).sum()) / stiffness
    return new, amplitude, iteration


def _update_dimensions(dims, factors, applied, amplitudes):
    """Galerkin-project each dimension's factors over all modes at once.

    With the other dimensions fixed, dimension d's factors Y (N_d, n) solve
    Σ_t A_t Y B_t = f hᵀ, B_t the Hadamard product of the other dimensions' Gram
    matrices. For two terms the pencil (B_1, B_0 + B_1) = W⁻ᵀ(Λ, I)W⁻¹ decouples it
    into n solves ((1 − λ_i) A_0 + λ_i A_1) z_i = f, Y = Z diag(Wᵀh) Wᵀ: divisions on
    a diagonal dimension, O(N) banded solves on the thickness. Updates ``factors``
    and ``applied`` in place and returns the amplitudes.
    """
    if len(applied[0]) != 2:
        raise NotImplementedError("the Galerkin update handles two-term operators (the Laplacian's split)")
    others = _others(len(dims))
    grams = [f.T @ a for f, a in zip(factors, applied)]  # (T, n, n) each
    loads = [f.T @ dim.load for f, dim in zip(factors, dims)]
    for d, dim in enumerate(dims):
        b = _product(grams, others[d], 0)
        h = _product(loads, others[d], 0)
        lam, w = _pencil(b[1], b[0] + b[1])
        y = (dim.solve_each(torch.stack([1 - lam, lam], dim=1)) * (w.T @ h)[None, :]) @ w.T
        amplitudes = y.norm(dim=0)
        # A mode the projection leaves empty keeps its factor, with amplitude zero.
        factors[d][:] = torch.where(amplitudes > 0, y / amplitudes.clamp_min(1e-300), factors[d])
        applied[d][:] = dim.apply(factors[d])
        grams[d] = factors[d].T @ applied[d]
        loads[d] = factors[d].T @ dim.load
    return amplitudes


def _pencil(b1: torch.Tensor, total: torch.Tensor, rcond: float = 1e-12):
    """λ (k,) and W (n, k) with Wᵀ·b1·W = diag(λ), Wᵀ·total·W = I.

    ``total`` (b0 + b1, positive semi-definite) loses rank numerically when modes
    become nearly dependent; its null space is dropped (a minimum-norm projection)
    rather than handed to a Cholesky factorisation that would fail or amplify noise.
    """
    s, q = torch.linalg.eigh(0.5 * (total + total.T))
    keep = s > rcond * s[-1]
    w = q[:, keep] / s[keep].sqrt()
    lam, z = torch.linalg.eigh(w.T @ (0.5 * (b1 + b1.T)) @ w)
    return lam.clamp(0.0, 1.0), w @ z
