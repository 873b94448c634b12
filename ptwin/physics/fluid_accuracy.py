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


def verify(basis: Basis, points: int = 1000, discrete_points: int = 6, seed: int = 0) -> dict:
    """Max relative force errors: vs the closed form over ``points`` random points and
    vs the direct discrete solve over ``discrete_points`` random points."""
    layer = FluidForce(basis, permeability=1e-16, viscosity=1.0)
    velocity, permeability, radius, height = random_points(points, basis, seed)
    x = height / radius

    def pgd(n):
        with torch.no_grad():
            return layer.evaluate(*(torch.from_numpy(a[:n]) for a in (velocity, radius, height, permeability))).numpy()

    scale = velocity * radius**3 / permeability
    closed = np.max(np.abs(pgd(points) / (force_coefficient(x) * scale) - 1))
    n = discrete_points
    discrete = np.max(np.abs(pgd(n) / (discrete_reference(basis, x[:n]) * scale[:n]) - 1))
    return {"points": points, "closed_form": float(closed), "discrete": float(discrete)}
