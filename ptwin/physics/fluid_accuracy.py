"""Errors of a basis as the fluid layer evaluates it: against the closed form, and
against the exact solution of the same discrete problem."""

from __future__ import annotations

import numpy as np
import torch

from ptwin.pgd.basis import Basis
from ptwin.pgd.problem import build_problem
from ptwin.pgd.reference import discrete_force_coefficient, force_coefficient
from ptwin.physics.fluid_force import FluidForce


def random_points(count: int, basis: Basis, seed: int = 0, aspect=(0.2, 1.0e4)):
    """Log-uniform (U, K, R, H) inside the basis grids with H/R in ``aspect``."""
    generator = np.random.default_rng(seed)

    def draw(low, high):
        return np.exp(generator.uniform(np.log(low), np.log(high), count))

    grids = basis.grids
    velocity = draw(*grids["velocity"][:2])
    permeability = draw(*grids["permeability"][:2])
    radius = draw(*grids["contact_radius"][:2])
    aspect_ratio = draw(*aspect)
    if "height" in grids:  # paper coordinates: keep H on its grid
        low, high = grids["height"][:2]
        radius = np.clip(radius, low / aspect_ratio, high / aspect_ratio)
    return velocity, permeability, radius, aspect_ratio * radius


def discrete_reference(basis: Basis, aspect_ratios: np.ndarray) -> np.ndarray:
    """c_h(x) of the discrete problem the basis approximates (Richardson-combined)."""
    config = basis.config
    fine = discrete_force_coefficient(build_problem(config), aspect_ratios)
    if not config.richardson:
        return fine
    coarse = discrete_force_coefficient(build_problem(config, rings=config.plane.rings // 2), aspect_ratios)
    ratio = 2.0**config.richardson_order
    return (ratio * fine - coarse) / (ratio - 1)


_CLOSED_FORM_ERRORS: dict[tuple[str, int, int], float] = {}  # per basis, once a process


def verify(basis: Basis, points: int = 1000, discrete_points: int = 6, seed: int = 0) -> dict:
    """Max relative force errors: vs the closed form over ``points`` random points and
    vs the direct discrete solve over ``discrete_points`` random points."""
    velocity, permeability, radius, height = (a[:discrete_points] for a in random_points(points, basis, seed))
    x = height / radius
    exact = discrete_reference(basis, x) * velocity * radius**3 / permeability
    discrete = np.max(np.abs(_layer_force(basis, velocity, radius, height, permeability) / exact - 1))
    closed = closed_form_error(basis, points, seed)
    return {"points": points, "closed_form": closed, "discrete": float(discrete)}


def closed_form_error(basis: Basis, points: int = 1000, seed: int = 0) -> float:
    """The largest relative error of the fluid layer's force against the closed form over ``points`` random points
    of the basis's grids: a bound on how far a K fitted through it sits from the K the exact Darcy force gives (the
    force is ∝ 1/K). Once a process per basis (30 ms for the default)."""
    key = (basis.config_hash, points, seed)
    if key not in _CLOSED_FORM_ERRORS:
        velocity, permeability, radius, height = random_points(points, basis, seed)
        exact = force_coefficient(height / radius) * velocity * radius**3 / permeability
        error = np.max(np.abs(_layer_force(basis, velocity, radius, height, permeability) / exact - 1))
        _CLOSED_FORM_ERRORS[key] = float(error)
    return _CLOSED_FORM_ERRORS[key]


def _layer_force(basis: Basis, *arrays: np.ndarray) -> np.ndarray:
    """The fluid layer's force at (velocity, radius, height, permeability) [N]."""
    layer = FluidForce(basis, permeability=1e-16, viscosity=1.0)
    with torch.no_grad():
        return layer.evaluate(*(torch.from_numpy(a) for a in arrays)).numpy()
