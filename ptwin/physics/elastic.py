"""Elastic laws of the solid network."""

from __future__ import annotations

from functools import partial

import numpy as np
import scipy.optimize
import torch
from torch import nn

from ptwin.physics.fluid_force import FluidForce
from ptwin.physics.kinematics import CurveKinematics, contact_radius, window_line


def hertz_force(depth: np.ndarray, effective_modulus: float, probe_radius: float) -> np.ndarray:
    """F = 4/3·E*·√ρ·w^1.5 [N] for depth w [m] (0 before contact)."""
    w = np.clip(depth, 0.0, None)
    return 4.0 / 3.0 * effective_modulus * np.sqrt(probe_radius) * w**1.5


def hertz_stiffness(depth: np.ndarray, effective_modulus: float, probe_radius: float) -> np.ndarray:
    """dF/dw = 2·E*·√(ρ w) [N/m]."""
    return 2.0 * effective_modulus * np.sqrt(probe_radius * np.clip(depth, 0.0, None))


class ReferenceElasticLaw(nn.Module):
    """F_el(w) [N] read off the reference (slowest) curve, differentiable in w and K.

    The reference force is smoothed onto ``nodes`` depths (local lines over ±1 node
    spacing, then isotonic: the solid law is monotone). Self-consistent (default,
    ``fluid`` given): its own Darcy force at the current K is subtracted at each node,
    F_el = F_ref − F_D(U_ref, K, R, H), so K flows through the law into every fit. With
    ``fluid=None`` the reference curve is taken as purely elastic (the paper's variant).
    Between nodes: linear interpolation (monotone nodes stay monotone); beyond the
    deepest node: the last segment. ``probe_radius`` ρ and ``sample_thickness`` H0 [m].
    """

    def __init__(
        self,
        reference: CurveKinematics,
        probe_radius: float,
        sample_thickness: float,
        fluid: FluidForce | None,
        nodes: int = 200,
    ):
        super().__init__()
        use = reference.in_contact
        order = np.argsort(reference.depth[use])
        depth, force = reference.depth[use][order], reference.force[use][order]
        velocity = reference.velocity[use][order]
        grid = np.linspace(0.0, depth[-1], nodes)
        spacing = grid[1] - grid[0]
        lo = np.searchsorted(depth, grid - spacing, side="left").clip(0, len(depth) - 2)
        hi = (np.searchsorted(depth, grid + spacing, side="right") - 1).clip(lo + 1, len(depth) - 1)
        smoothed, _ = window_line(depth, force, lo, hi, grid)
        local_velocity, _ = window_line(depth, velocity, lo, hi, grid)
        smoothed = scipy.optimize.isotonic_regression(smoothed).x
        as_tensor = partial(torch.tensor, dtype=torch.float64)
        self.register_buffer("depth_nodes", as_tensor(grid))
        self.register_buffer("reference_force", as_tensor(smoothed))
        self.register_buffer("velocity", as_tensor(local_velocity))
        self.register_buffer("radius", as_tensor(contact_radius(grid, probe_radius)))
        self.register_buffer("height", as_tensor(sample_thickness - grid))
        self.fluid = fluid

    def node_forces(self, permeability: torch.Tensor | None = None) -> torch.Tensor:
        """F_el at the depth nodes for K = ``permeability`` (default: the fluid layer's)."""
        if self.fluid is None:
            return self.reference_force
        k = self.fluid.permeability if permeability is None else permeability
        return self.reference_force - self.fluid.evaluate(self.velocity, self.radius, self.height, k)

    def forward(self, depth: torch.Tensor, permeability: torch.Tensor | None = None) -> torch.Tensor:
        values = self.node_forces(permeability)
        spacing = self.depth_nodes[1] - self.depth_nodes[0]
        position = depth.clamp(min=0.0) / spacing
        index = position.detach().floor().clamp(0, values.numel() - 2).long()
        t = position - index
        return values[index] * (1 - t) + values[index + 1] * t
