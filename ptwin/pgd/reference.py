"""References the PGD basis is verified against.

- ``force_coefficient``: the closed form c(x) = 4π Σ_n coth(j_n x)/j_n³, so that the
  fluid force on a cylinder of radius R and height H = xR is c(x)·μ·U·R³/K.
- ``bessel_pressure``: the pressure field as a Bessel series.
- ``discrete_force_coefficient``: the force of the exact solution of the same
  discrete problem the PGD solves, by fast diagonalisation (one tridiagonal solve
  per eigenmode of the in-plane pencil).
"""

from __future__ import annotations

import numpy as np
import scipy.special
import torch

from ptwin.pgd.problem import DiscreteProblem

_ZEROS = scipy.special.jn_zeros(0, 4000)
# c(∞) = 4π Σ 1/j_n³, with the tail n > N (j_n ≈ (n − 1/4)π): (4/π²)·1/(2(N + 1/4)²).
_C_INFINITY = 4 * np.pi * np.sum(1.0 / _ZEROS**3) + 2.0 / (np.pi**2 * (len(_ZEROS) + 0.25) ** 2)
_SATURATED = 20.0  # coth(y) − 1 = 2/(e^{2y} − 1) < 1e-17 for y > 20


def force_coefficient(aspect_ratio: np.ndarray | float) -> np.ndarray:
    """c(x) for aspect ratios x = H/R > 0 (relative accuracy ~1e-12): c(∞) plus the terms whose
    coth(j_n x) still differs from 1 (none once x > 20/j_1 ≈ 8, so thick samples cost O(1))."""
    x = np.asarray(aspect_ratio, dtype=np.float64)
    terms = int(np.searchsorted(_ZEROS, _SATURATED / x.min())) if x.size else 0
    if terms == 0:  # every coth has saturated; the simulator asks this on thick samples at every step
        return _C_INFINITY + 0.0 * x
    j = _ZEROS[:terms]
    with np.errstate(over="ignore"):  # e^{2jx} = inf past saturation: its term is 2/inf = 0, as it should be
        correction = 4 * np.pi * np.sum(2.0 / (np.expm1(2 * j * x[..., None]) * j**3), axis=-1)
    return _C_INFINITY + correction


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


def discrete_force_coefficient(problem: DiscreteProblem, aspect_ratios) -> np.ndarray:
    """c_h(x): the force coefficient of the discrete problem, for each x.

    The in-plane dimension is already diagonal (the eigenbasis of its pencil), so the
    exact discrete solution is one tridiagonal φ solve per in-plane mode λ, with
    coefficients (x·λ, 1/x), weighted by the squared top integral of that mode.
    """
    plane, thickness = problem.dims.plane, problem.dims.thickness
    eigenvalues, weights = plane.term_coefficients[0].tolist(), (plane.load**2).tolist()
    top = thickness.load
    return np.array(
        [
            sum(
                w * thickness.solve(torch.tensor([x * lam, 1 / x], dtype=torch.float64), top)[-1].item()
                for lam, w in zip(eigenvalues, weights)
            )
            for x in np.atleast_1d(aspect_ratios)
        ]
    )
