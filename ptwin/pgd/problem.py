"""The Darcy problem as a separated operator, in scaled or in the paper's coordinates.

Weak form (μ = 1; the pressure scales exactly with μ):
    ∫ K [ H ∇ξζP·∇ξζP* + (R²/H) ∂φP ∂φP* ] = ∫_{φ=1} P* U R²
Scaled coordinates divide by R and use the aspect ratio x = H/R: coefficients K·R·x
and K·R/x. The parameter dimensions are weighted by their log-measure over the
energy scale U²R³/K, so every corner of the box counts alike.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.linalg
import torch

from ptwin.pgd.config import Grid, PGDConfig
from ptwin.pgd.dimensions import BandedDimension, DiagonalDimension, ParameterDimension
from ptwin.pgd.fem import interval_matrices, triangle_matrices
from ptwin.pgd.mesh import graded_thickness, unit_disc

# Energy-scale exponent of each parameter: weight ∝ p**exponent × d(log p).
_ENERGY_WEIGHT = {"velocity": -2.0, "permeability": 1.0, "contact_radius": -3.0, "height": 0.0, "aspect_ratio": 0.0}


class Dimensions(NamedTuple):
    """The six factor spaces of the separated Darcy problem, in the operator's order."""

    plane: DiagonalDimension  # the unit disc, in the eigenbasis of its pencil
    thickness: BandedDimension  # φ = z/H
    velocity: ParameterDimension
    permeability: ParameterDimension
    contact_radius: ParameterDimension
    shape: ParameterDimension  # aspect ratio H/R (scaled coordinates) or height H (paper)

    @property
    def parameters(self) -> tuple[ParameterDimension, ...]:
        """The four parameter dimensions, in the order of the basis's force functions."""
        return (self.velocity, self.permeability, self.contact_radius, self.shape)


@dataclass
class DiscreteProblem:
    """The separated operator plus what is needed to read forces and fields back.

    The in-plane dimension lives in the eigenbasis of its pencil: a factor a there is
    the nodal field ``plane_modes @ a``, and its top integral is ``dims.plane.load @ a``.
    """

    dims: Dimensions
    n_terms: int
    plane_nodes: np.ndarray  # (N, 2) all in-plane nodes
    plane_free: np.ndarray  # (N,) bool, not on the Dirichlet rim
    plane_triangles: np.ndarray
    plane_modes: torch.Tensor  # (N_free, N_free) mass-orthonormal eigenvectors
    thickness_nodes: np.ndarray  # (M,)


def log_grid(grid: Grid) -> torch.Tensor:
    return torch.logspace(np.log10(grid.minimum), np.log10(grid.maximum), grid.nodes, dtype=torch.float64)


def _parameter(name: str, grid: Grid, coefficients, load) -> ParameterDimension:
    nodes = log_grid(grid)
    step = np.log(grid.maximum / grid.minimum) / (grid.nodes - 1)
    trapezoid = torch.full_like(nodes, step)
    trapezoid[[0, -1]] *= 0.5
    weight = trapezoid * nodes ** _ENERGY_WEIGHT[name]
    terms = torch.stack([c(nodes) for c in coefficients]) * weight
    return ParameterDimension(name, terms, load(nodes) * weight, nodes)


def build_problem(config: PGDConfig, rings: int | None = None) -> DiscreteProblem:
    """Assemble the separated operator; ``rings`` overrides the in-plane mesh size."""
    nodes, triangles, rim = unit_disc(rings or config.plane.rings, config.plane.ring_density, config.plane.edge_grading)
    stiffness, mass = triangle_matrices(nodes, triangles)
    free = ~rim
    top_integral = np.asarray(mass[free].sum(axis=1)).ravel()  # ∫_disc of each free basis function
    # S V = M V Λ with VᵀMV = I: term 0 (∇ξζ) is diag(λ), term 1 (∂φ) the identity.
    eigenvalues, modes = scipy.linalg.eigh(stiffness[free][:, free].toarray(), mass[free][:, free].toarray())
    coefficients = torch.from_numpy(np.stack([eigenvalues, np.ones_like(eigenvalues)]))
    plane = DiagonalDimension("plane", coefficients, torch.from_numpy(modes.T @ top_integral))
    phi = graded_thickness(config.thickness.nodes, config.thickness.finest)
    z_stiffness, z_mass = interval_matrices(phi)
    top = torch.zeros(len(phi), dtype=torch.float64)
    top[-1] = 1.0
    # Term 0 (∇ξζ) carries the φ mass, term 1 (∂φ) the φ stiffness.
    thickness = BandedDimension(
        "thickness", z_stiffness, z_mass, torch.tensor([[0.0, 1.0], [1.0, 0.0]], dtype=torch.float64), top
    )
    one = torch.ones_like
    velocity = _parameter("velocity", config.velocity, [one, one], lambda u: u)
    permeability = _parameter("permeability", config.permeability, [lambda k: k, lambda k: k], one)
    if config.coordinates == "scaled":
        radius = _parameter("contact_radius", config.contact_radius, [lambda r: r, lambda r: r], lambda r: r**2)
        shape = _parameter("aspect_ratio", config.aspect_ratio, [lambda x: x, lambda x: 1 / x], one)
    else:
        radius = _parameter("contact_radius", config.contact_radius, [one, lambda r: r**2], lambda r: r**2)
        shape = _parameter("height", config.height, [lambda h: h, lambda h: 1 / h], one)
    return DiscreteProblem(
        Dimensions(plane, thickness, velocity, permeability, radius, shape),
        2,
        nodes,
        free,
        triangles,
        torch.from_numpy(modes),
        phi,
    )
