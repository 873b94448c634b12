"""From a separated pressure to a recompressed separated *force* over the parameters.

F_D/μ = R² ∫_top P = Σ_i β_i u_i(U) l_i(K) [R² r_i(R)] s_i(x or H), with β_i the
amplitude times the top integral of the in-plane and thickness factors. A row-scaled
SVD per parameter dimension then truncates each dimension to its numerical rank
(U, K and, in scaled coordinates, R collapse to rank 1) and a Tucker core couples them.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ptwin.pgd.enrichment import SeparatedSolution
from ptwin.pgd.problem import Dimensions


@dataclass
class SeparatedForce:
    """F/μ = Σ_{a,b,c,d} core[a,b,c,d] f0[:,a](p0) f1[:,b](p1) f2[:,c](p2) f3[:,d](p3).

    functions[d]: (N_d, r_d) values on the log-uniform grid of parameter d."""

    names: list[str]
    functions: list[torch.Tensor]
    core: torch.Tensor


def force_amplitudes(amplitudes, plane, thickness, top_integral: torch.Tensor) -> torch.Tensor:
    """β_i = α_i·(∫_disc plane_i)·thickness_i(φ = 1): each mode's force per parameter
    product; ``top_integral`` (N_plane,) integrates a plane factor over the disc."""
    return amplitudes * (top_integral @ plane) * thickness[-1]


def force_modes(solution: SeparatedSolution, dims: Dimensions):
    """(β, parameter factors in the order of ``dims.parameters``) of the force of one
    separated pressure solution: F/μ = R²·∫_top P, so the radius factor takes R²."""
    factors = dict(zip(solution.names, solution.factors))
    beta = force_amplitudes(solution.amplitudes, factors["plane"], factors["thickness"], dims.plane.load)
    factors["contact_radius"] = factors["contact_radius"] * dims.contact_radius.nodes[:, None] ** 2
    return beta, [factors[dim.name] for dim in dims.parameters]


def recompress(
    names: list[str], beta: torch.Tensor, parameters: list[torch.Tensor], tol: float = 1e-11
) -> SeparatedForce:
    """Truncate each parameter dimension to its numerical rank (relative ``tol``)."""
    functions, couplings = [], []
    for factors in parameters:
        scale = factors.abs().amax(dim=1, keepdim=True).clamp_min(1e-300)
        left, singular, right_t = torch.linalg.svd(factors / scale, full_matrices=False)
        rank = int((singular > tol * singular[0]).sum())
        functions.append(scale * left[:, :rank])
        couplings.append(singular[:rank, None] * right_t[:rank])
    core = torch.einsum("i,ai,bi,ci,di->abcd", beta, *couplings)
    ranks = list(core.shape)
    if sorted(ranks)[:-1] == [1] * (len(ranks) - 1):
        # All dimensions but one are rank 1: fold the core into that one.
        wide = max(range(len(ranks)), key=lambda d: ranks[d])
        functions[wide] = functions[wide] @ core.reshape(-1, 1)
        core = torch.ones([1] * len(ranks), dtype=core.dtype)
    return SeparatedForce(names, functions, core)
