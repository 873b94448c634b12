"""References the PGD basis is verified against.

- ``force_coefficient``: the closed form c(x) = 4π Σ_n coth(j_n x)/j_n³, so that the
  fluid force on a cylinder of radius R and height H = xR is c(x)·μ·U·R³/K.
- ``bessel_pressure``: the pressure field as a Bessel series.
- ``discrete_force_coefficient``: the force of the exact solution of the same
  discrete problem the PGD solves, by fast diagonalisation (a generalised
  eigendecomposition of the in-plane pencil, one tridiagonal solve per mode).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
import scipy.special

from ptwin.pgd.dimensions import solve_tridiagonal
from ptwin.pgd.problem import DiscreteProblem

_ZEROS = scipy.special.jn_zeros(0, 4000)


def force_coefficient(aspect_ratio: np.ndarray | float) -> np.ndarray:
    """c(x) for aspect ratios x = H/R > 0 (relative accuracy ~1e-12)."""
    x = np.asarray(aspect_ratio, dtype=np.float64)[..., None]
    series = 4 * np.pi * np.sum(1.0 / (np.tanh(_ZEROS * x) * _ZEROS**3), axis=-1)
    # Tail n > N with j_n ≈ (n − 1/4)π and coth = 1: (4/π²)·1/(2(N + 1/4)²).
    tail = 2.0 / (np.pi**2 * (len(_ZEROS) + 0.25) ** 2)
    return series + tail


def bessel_pressure(r, z, *, velocity, permeability, contact_radius, height, viscosity=1.0, terms=2000):
    """Darcy pressure [Pa] at radius r and height z [m] (z = H is the loaded top)."""
    r = np.asarray(r, dtype=np.float64)[..., None] / contact_radius
    z = np.asarray(z, dtype=np.float64)[..., None] / contact_radius
    j = _ZEROS[:terms]
    x = height / contact_radius
    # cosh(j z)/sinh(j x) written with decaying exponentials only (no overflow).
    ratio = (np.exp(j * (z - x)) + np.exp(-j * (z + x))) / (1 - np.exp(-2 * j * x))
    series = np.sum(scipy.special.j0(j * r) * ratio / (j**2 * scipy.special.j1(j)), axis=-1)
    return 2 * viscosity * velocity * contact_radius / permeability * series


def _plane_modes(problem: DiscreteProblem):
    plane = problem.dims[0]
    values, vectors = scipy.linalg.eigh(plane.stiffness.toarray(), plane.mass.toarray())
    return values, vectors


def _thickness_solve(problem, aspect_ratio, eigenvalue, rhs):
    thickness = problem.dims[1]
    return solve_tridiagonal(aspect_ratio * eigenvalue * thickness.mass + thickness.stiffness / aspect_ratio, rhs)


def discrete_force_coefficient(problem: DiscreteProblem, aspect_ratios) -> np.ndarray:
    """c_h(x): the force coefficient of the discrete problem, for each x.

    Diagonalises the in-plane pencil (the graded φ pencil is far too ill-conditioned
    for a dense eigensolver), then one tridiagonal solve per in-plane mode.
    """
    values, vectors = _plane_modes(problem)
    weights = (vectors.T @ problem.top_integral.numpy()) ** 2
    top = np.zeros(len(problem.thickness_nodes))
    top[-1] = 1.0
    return np.array(
        [
            sum(w * _thickness_solve(problem, x, lam, top)[-1] for lam, w in zip(values, weights))
            for x in np.atleast_1d(aspect_ratios)
        ]
    )
