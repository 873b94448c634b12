"""Greedy rank-one PGD enrichment with an alternating-directions fixed point.

Solves Σ_t ⊗_d A_t^d u = ⊗_d f^d for u = Σ_i α_i ⊗_d F_i^d. Every factor F_i^d is
kept at unit norm and its scale in α_i: products over six dimensions otherwise span
1e-100. After each new mode the parameter dimensions get a Galerkin update over all
modes (cheap: their operators are diagonal), which is what lets greedy PGD converge.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import scipy.linalg
import torch

from ptwin.pgd.dimensions import FEDimension, ParameterDimension

Dimension = FEDimension | ParameterDimension


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


@dataclass
class EnrichmentSettings:
    """Stopping and fixed-point controls of the greedy enrichment."""

    max_modes: int = 150
    amplitude_tol: float = 1e-5
    output_tol: float = 1e-7
    fixed_point_tol: float = 1e-8
    max_fixed_point_iterations: int = 25
    seed: int = 0


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
    factors = [torch.zeros(dim.size, 0, dtype=torch.float64) for dim in dims]
    applied = [[torch.zeros(dim.size, 0, dtype=torch.float64)] * n_terms for dim in dims]
    amplitudes = torch.zeros(0, dtype=torch.float64)
    history: list[dict] = []
    start = time.perf_counter()
    small_in_a_row = 0
    previous_output = None
    for mode in range(settings.max_modes):
        new, amplitude, iterations = _new_mode(dims, n_terms, factors, applied, amplitudes, settings, generator)
        factors = [torch.cat([f, g[:, None]], dim=1) for f, g in zip(factors, new)]
        amplitudes = torch.cat([amplitudes, amplitude.reshape(1)])
        for d, dim in enumerate(dims):
            applied[d] = [torch.cat([applied[d][t], dim.apply(t, new[d][:, None])], dim=1) for t in range(n_terms)]
        amplitudes = _update_parameter_dimensions(dims, n_terms, factors, applied, amplitudes)
        relative_amplitude = float(amplitude.abs() / amplitudes.abs().max())
        change = 1.0
        if output is not None:
            current = output(factors, amplitudes)
            if previous_output is not None:
                change = float(((current - previous_output) / current).abs().max())
            previous_output = current
        entry = {
            "mode": mode + 1,
            "relative_amplitude": relative_amplitude,
            "output_change": change,
            "iterations": iterations,
            "seconds": time.perf_counter() - start,
        }
        history.append(entry)
        progress(
            f"mode {mode + 1:4d}  amplitude {relative_amplitude:.2e}  output change {change:.2e}"
            f"  fixed-point its {iterations:2d}  {entry['seconds']:6.2f} s"
        )
        converged = relative_amplitude < settings.amplitude_tol or change < settings.output_tol
        small_in_a_row = small_in_a_row + 1 if converged else 0
        if small_in_a_row >= 2:
            break
    progress(f"stopped after {len(history)} modes, last output change {history[-1]['output_change']:.2e}")
    return SeparatedSolution([dim.name for dim in dims], factors, amplitudes, history)


def _new_mode(dims, n_terms, factors, applied, amplitudes, settings, generator):
    """Alternating-directions fixed point for the next rank-one correction."""
    n_dims = len(dims)
    new = []
    for dim in dims:
        start = dim.load + 0.5 * dim.load.abs().max() * torch.rand(dim.size, generator=generator, dtype=torch.float64)
        new.append(start / start.norm())
    own = torch.empty(n_terms, n_dims, dtype=torch.float64)  # F_d^T A_t^d F_d
    loads = torch.empty(n_dims, dtype=torch.float64)  # F_d^T f^d
    prior = torch.empty(n_terms, n_dims, amplitudes.numel(), dtype=torch.float64)  # F_d^T A_t^d F_i^d

    def project(d):
        for t in range(n_terms):
            own[t, d] = new[d] @ dims[d].apply(t, new[d][:, None])[:, 0]
            prior[t, d] = new[d] @ applied[d][t]
        loads[d] = new[d] @ dims[d].load

    for d in range(n_dims):
        project(d)
    for iteration in range(1, settings.max_fixed_point_iterations + 1):  # noqa: B007 (returned)
        previous = [f.clone() for f in new]
        for d in range(n_dims):
            others = [e for e in range(n_dims) if e != d]
            coefficients = own[:, others].prod(dim=1)
            rhs = loads[others].prod() * dims[d].load
            for t in range(n_terms):
                rhs = rhs - applied[d][t] @ (amplitudes * prior[t][others].prod(dim=0))
            solution = dims[d].solve(coefficients, rhs)
            new[d] = solution / solution.norm()
            project(d)
        overlap = torch.stack([f @ g for f, g in zip(new, previous)]).prod().abs()
        if 1.0 - overlap < settings.fixed_point_tol:
            break
    stiffness = own.prod(dim=1).sum()
    amplitude = (loads.prod() - (amplitudes * prior.prod(dim=1)).sum()) / stiffness
    return new, amplitude, iteration


def _update_parameter_dimensions(dims, n_terms, factors, applied, amplitudes):
    """Galerkin-project each parameter dimension's factors over all modes at once.

    With the other dimensions fixed the system decouples per grid node j into an
    n×n system (Σ_t c_t(j) B_t) y_j = f(j) h. For two terms it is a matrix pencil:
    one generalised eigendecomposition serves every node.
    """
    if n_terms != 2:
        raise NotImplementedError("the Galerkin update handles two-term operators (the Laplacian's split)")
    grams = [[factors[e].T @ applied[e][t] for t in range(n_terms)] for e in range(len(dims))]
    loads = [factors[e].T @ dims[e].load for e in range(len(dims))]
    for d, dim in enumerate(dims):
        if not isinstance(dim, ParameterDimension):
            continue
        others = [e for e in range(len(dims)) if e != d]
        b = [torch.stack([grams[e][t] for e in others]).prod(dim=0) for t in range(n_terms)]
        h = torch.stack([loads[e] for e in others]).prod(dim=0)
        total = 0.5 * (b[0] + b[1] + (b[0] + b[1]).T)
        # b0 + b1 is positive definite even where one term alone is nearly singular.
        eigenvalues, vectors = scipy.linalg.eigh(0.5 * (b[1] + b[1].T).numpy(), total.numpy())
        lam, w = torch.from_numpy(eigenvalues), torch.from_numpy(vectors)
        c0, c1 = dim.term_coefficients
        diagonal = c0[:, None] * (1 - lam)[None, :] + c1[:, None] * lam[None, :]
        y = (dim.load[:, None] * (w.T @ h)[None, :] / diagonal) @ w.T
        amplitudes = y.norm(dim=0)
        factors[d][:] = y / amplitudes
        applied[d] = [dim.apply(t, factors[d]) for t in range(n_terms)]
        grams[d] = [factors[d].T @ applied[d][t] for t in range(n_terms)]
        loads[d] = factors[d].T @ dim.load
    return amplitudes
