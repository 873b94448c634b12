"""Elastic laws of the solid network."""

from __future__ import annotations

from functools import partial

import numpy as np
import scipy.optimize
import torch
from torch import nn

from ptwin.physics.fluid_force import FluidForce
from ptwin.physics.kinematics import CurveKinematics, contact_radius, window_line
from ptwin.physics.samples import Samples


def hertz_force(depth: np.ndarray, effective_modulus: float, probe_radius: float) -> np.ndarray:
    """F = 4/3·E*·√ρ·w^1.5 [N] for depth w [m] (0 before contact)."""
    w = np.clip(depth, 0.0, None)
    return 4.0 / 3.0 * effective_modulus * np.sqrt(probe_radius) * w**1.5


def hertz_stiffness(depth: np.ndarray, effective_modulus: float, probe_radius: float) -> np.ndarray:
    """dF/dw = 2·E*·√(ρ w) [N/m]."""
    return 2.0 * effective_modulus * np.sqrt(probe_radius * np.clip(depth, 0.0, None))


class ReferenceElasticLaw(nn.Module):
    """F_el(w) [N] read off the reference (slowest) curve, differentiable in w and K.

    The reference force is smoothed onto ``nodes`` depths by local lines in w^1.5 over
    ``smoothing`` (fraction) of the curve's samples — a sphere's force is close to
    linear in w^1.5, so the smoothing adds no bias where the curve bends — then made
    isotonic (the solid law is monotone). The nodes also carry the reference curve's
    time, velocity, contact radius and height (``node_samples``), so that a force model
    can subtract its own rate-dependent forces there. Self-consistent (``fluid`` given):
    F_el = F_ref − F_D(U_ref, K, R, H); with ``fluid=None`` the reference curve is taken
    as purely elastic (the paper's variant). Between nodes: linear interpolation
    (monotone nodes stay monotone); beyond the deepest node: the last segment.
    ``probe_radius`` ρ and ``sample_thickness`` H0 [m].
    """

    def __init__(
        self,
        reference: CurveKinematics,
        probe_radius: float,
        sample_thickness: float,
        fluid: FluidForce | None,
        nodes: int = 200,
        smoothing: float = 0.05,
    ):
        super().__init__()
        use = reference.in_contact
        order = np.argsort(reference.depth[use])
        depth, force = reference.depth[use][order], reference.force[use][order]
        grid = np.linspace(0.0, depth[-1], nodes)
        position = np.searchsorted(depth, grid)
        half = max(int(smoothing * len(depth) / 2), int(np.ceil(len(depth) / nodes)), 2)
        lo = (position - half).clip(0, len(depth) - 3)
        hi = (position + half).clip(lo + 2, len(depth) - 1)

        def local(values):
            return window_line(depth**1.5, values, lo, hi, grid**1.5)[0]

        as_tensor = partial(torch.tensor, dtype=torch.float64)
        self.register_buffer("depth_nodes", as_tensor(grid))
        self.register_buffer("reference_force", as_tensor(scipy.optimize.isotonic_regression(local(force)).x))
        self.register_buffer("time", as_tensor(np.maximum.accumulate(local(reference.time[use][order]))))
        self.register_buffer("velocity", as_tensor(local(reference.velocity[use][order])))
        self.register_buffer("radius", as_tensor(contact_radius(grid, probe_radius)))
        self.register_buffer("height", as_tensor(sample_thickness - grid))
        self.base_speed = reference.base_speed
        self.fluid = fluid

    def node_samples(self) -> Samples:
        """The reference curve at the depth nodes, as one curve of samples."""
        n = self.depth_nodes.numel()
        return Samples(
            time=self.time,
            depth=self.depth_nodes,
            velocity=self.velocity,
            base_speed=torch.full_like(self.time, self.base_speed),
            force=self.reference_force,
            start=torch.arange(n, device=self.time.device) == 0,
            curve=torch.zeros(n, dtype=torch.long, device=self.time.device),
            in_contact=torch.ones(n, dtype=torch.bool, device=self.time.device),
            noise_floor=torch.zeros_like(self.time),
            curve_ids=("reference",),
        )

    def node_forces(self, permeability: torch.Tensor | None = None, nodes: torch.Tensor | None = None):
        """F_el at the depth nodes (or those indexed by ``nodes``) for K = ``permeability`` (default: the
        fluid layer's; one K, or one per indexed node)."""
        pick = slice(None) if nodes is None else nodes
        if self.fluid is None:
            return self.reference_force[pick]
        k = self.fluid.permeability if permeability is None else permeability
        fluid = self.fluid.evaluate(self.velocity[pick], self.radius[pick], self.height[pick], k)
        return self.reference_force[pick] - fluid

    def bracket(self, depth: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(index of the node below, fraction of the way to the next) for each depth."""
        spacing = self.depth_nodes[1] - self.depth_nodes[0]
        position = depth.clamp(min=0.0) / spacing
        index = position.detach().floor().clamp(0, self.depth_nodes.numel() - 2).long()
        return index, position - index

    def interpolate(self, node_values: torch.Tensor, depth: torch.Tensor) -> torch.Tensor:
        """Linear interpolation of values at the depth nodes to ``depth`` [m]."""
        index, t = self.bracket(depth)
        return node_values[index] * (1 - t) + node_values[index + 1] * t

    def forward(self, depth: torch.Tensor, permeability: torch.Tensor | None = None) -> torch.Tensor:
        """F_el(depth); ``permeability`` one K [m²] or one per depth (pointwise identification)."""
        if permeability is None or permeability.numel() == 1 or self.fluid is None:
            return self.interpolate(self.node_forces(permeability), depth)
        index, t = self.bracket(depth)
        return self.node_forces(permeability, index) * (1 - t) + self.node_forces(permeability, index + 1) * t
