"""The elastic solid: the Hertz law (a closed form for tests and the simulator) and the
reference curve that ptwin's self-consistent elastic law is read off."""

from __future__ import annotations

from dataclasses import fields
from functools import partial

import numpy as np
import scipy.optimize
import torch
from torch import nn

from ptwin.data.kinematics import CurveKinematics, window_line
from ptwin.data.recordings import APPROACH
from ptwin.physics.samples import Samples


def hertz_force(depth, effective_modulus: float, probe_radius: float):
    """F = 4/3·E*·√ρ·w^1.5 [N] for depth w [m] (0 before contact); an array or one float (the simulator's
    right-hand side, called thousands of times a curve: ufuncs, no array wrapping)."""
    return 4.0 / 3.0 * effective_modulus * np.sqrt(probe_radius) * np.maximum(depth, 0.0) ** 1.5


def hertz_stiffness(depth, effective_modulus: float, probe_radius: float):
    """dF/dw = 2·E*·√(ρ w) [N/m]; an array or one float, as ``hertz_force``."""
    return 2.0 * effective_modulus * np.sqrt(probe_radius * np.maximum(depth, 0.0))


class ReferenceCurve(nn.Module):
    """The reference (slowest) curve on depth nodes: what the elastic law is read off.

    The reference force is smoothed onto ``nodes`` depths by local lines in w^1.5 over
    ``smoothing`` (fraction) of the curve's samples — a sphere's force is close to
    linear in w^1.5, so the smoothing adds no bias where the curve bends — then made
    isotonic (the solid law is monotone). The nodes also carry the curve's time and
    velocity (``node_samples``), so that a force model can evaluate its own
    rate-dependent forces there (``ForceModel.elastic_nodes``). Between nodes: linear
    interpolation (monotone nodes stay monotone). Beyond the deepest node the law is continued as a
    sphere's: a line in w^1.5 through the deepest ``TAIL`` of the nodes (exact for Hertz; first-order
    exact for any law), up to ``CONTINUED`` of the reference's depth further. That is where a hold's tip
    creeps on as the force relaxes through the cantilever (the force falls, so w = z − F/k_s grows): on
    a curve held at the reference's own depth every hold sample lies beyond its deepest approach sample;
    and where a creep at constant force sinks in. (Approach samples deeper than the reference are not
    fitted: a deeper approach would need a deeper reference.)
    """

    TAIL = 0.1  # fraction of the nodes (the deepest) the continuation's slope is read off
    CONTINUED = 0.25  # how far beyond the reference's depth (fraction of it) the continued law is used

    @staticmethod
    def read_from(reference: CurveKinematics) -> np.ndarray:
        """bool: the reference's samples the law is read off, its approach in contact (F(w) there is a function)."""
        return reference.in_contact & (reference.segment == APPROACH)

    def __init__(self, reference: CurveKinematics, nodes: int = 200, smoothing: float = 0.05):
        super().__init__()
        use = self.read_from(reference)
        order = np.argsort(reference.depth[use])
        depth, force = reference.depth[use][order], reference.force[use][order]
        grid = np.linspace(0.0, depth[-1], nodes)
        position = np.searchsorted(depth, grid)
        half = max(int(smoothing * len(depth) / 2), int(np.ceil(len(depth) / nodes)), 2)
        lo = (position - half).clip(0, len(depth) - 3)
        hi = (position + half).clip(lo + 2, len(depth) - 1)

        x, at = depth**1.5, grid**1.5
        self._window = (x, lo, hi, at)
        local = self.smooth
        # The law's stiffness dF/dw at the nodes, from the same local lines (slope b in w^1.5: 1.5·b·√w); a solid's
        # is not negative, whatever the noise makes of a line.
        slope = window_line(x, force, lo, hi, at)[1]
        self._stiffness = np.maximum(1.5 * slope, 0.0) * np.sqrt(grid)

        as_tensor = partial(torch.tensor, dtype=torch.float64)
        self.register_buffer("depth_nodes", as_tensor(grid))
        self.register_buffer("reference_force", as_tensor(scipy.optimize.isotonic_regression(local(force)).x))
        self.register_buffer("time", as_tensor(np.maximum.accumulate(local(reference.time[use][order]))))
        self.register_buffer("velocity", as_tensor(local(reference.velocity[use][order])))
        self.base_speed = reference.base_speed
        self.curve = reference.curve
        self.noise_std = reference.noise.std  # [N]: what the law inherits of the reference's noise
        self.samples = depth.size  # the reference's samples the law is read off
        self._after = None  # ``after``'s last (key, value)
        tail = grid[-max(2, int(self.TAIL * nodes)) :] ** 1.5
        self.register_buffer("tail_slope", as_tensor((tail - tail.mean()) / np.sum((tail - tail.mean()) ** 2)))

    @property
    def deepest(self) -> float:
        """The reference's deepest depth [m]: where the law read off it ends."""
        return float(self.depth_nodes[-1])

    @property
    def known_depth(self) -> float:
        """The deepest depth [m] the law is used at in a hold or a creep (continued beyond ``deepest``)."""
        return (1.0 + self.CONTINUED) * self.deepest

    def stiffness(self, depth: np.ndarray) -> np.ndarray:
        """The law's dF/dw [N/m] at ``depth`` [m]: between the nodes as read off the local lines, beyond the
        deepest node the continued sphere's (1.5·b·√w, b its line's slope in w^1.5), 0 before contact."""
        w = np.maximum(depth, 0.0)
        beyond = 1.5 * float(self.continued_slope(self.reference_force)) * np.sqrt(w)
        return np.where(w > self.deepest, beyond, np.interp(w, self.depth_nodes.cpu().numpy(), self._stiffness))

    def noise_gain(self, depth: np.ndarray, spring_constant: float) -> np.ndarray:
        """1 + s/k_s at ``depth`` [m] (s the law's stiffness there, k_s the cantilever's [N/m]): what a sample's
        force noise becomes in its residual. The depth w = z − F/k_s is read off the measured force, so noise n in
        the force moves the depth by −n/k_s and the law by −s·n/k_s, and the residual carries n·(1 + s/k_s): on
        the realism suite's soft cantilever up to 1.2 at the deepest samples, the residuals' χ² in contact 1.3× the
        noise's on average without it. A force added at the tip reaches the recording divided by it
        (``ptwin.pipeline.inject``)."""
        return 1.0 + self.stiffness(depth) / spring_constant

    def continued_slope(self, node_values: torch.Tensor) -> torch.Tensor:
        """The slope in w^1.5 of the line that values at the depth nodes ((nodes,) or (nodes, …)) continue along
        beyond the deepest (the class docstring): fitted through the deepest ``TAIL`` of them."""
        return torch.tensordot(self.tail_slope, node_values[-self.tail_slope.numel() :], dims=1)

    def smooth(self, values: np.ndarray) -> np.ndarray:
        """Values on the reference's samples (in depth order; (samples, …)) smoothed onto the depth nodes as the
        law is, before the isotonic step: local lines in w^1.5. Linear in ``values``."""
        x, lo, hi, at = self._window
        return window_line(x, values, lo, hi, at)[0]

    def node_samples(self, index: torch.Tensor | None = None) -> Samples:
        """The reference curve at the depth nodes (or those indexed by ``index``), as samples of one curve."""
        pick = slice(None) if index is None else index
        time = self.time[pick]
        n = time.numel()
        return Samples(
            time=time,
            depth=self.depth_nodes[pick],
            velocity=self.velocity[pick],
            base_speed=torch.full_like(time, self.base_speed),
            force=self.reference_force[pick],
            start=torch.arange(n, device=time.device) == 0,
            curve=torch.zeros(n, dtype=torch.long, device=time.device),
            in_contact=torch.ones(n, dtype=torch.bool, device=time.device),
            noise_floor=torch.zeros_like(time),
            curve_ids=(f"{self.curve}'s depth nodes",),  # what an error names: nodes, not the curve's samples
        )

    def after(self, samples: Samples) -> tuple[Samples, Samples]:
        """(``samples`` followed by the depth nodes' ``node_samples``, the node samples): what a self-consistent
        model evaluates its rate forces on in one pass. Kept for the samples last given while neither they nor the
        nodes change (the same tensors, none written into): a fit evaluates the same samples at every step, and
        joining them anew cost 0.2 ms each time (3% of a bench-map spot)."""
        parts = (*(getattr(samples, f.name) for f in fields(samples)), *self.buffers())
        key = [(part, part._version if torch.is_tensor(part) else None) for part in parts]
        kept = self._after
        same = kept is not None and len(kept[0]) == len(key)
        if not (same and all(a is b and u == v for (a, u), (b, v) in zip(kept[0], key))):
            nodes = self.node_samples()
            kept = self._after = (key, (samples.join(nodes), nodes))
        return kept[1]

    def bracket(self, depth: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(index of the node below, fraction of the way to the next) for each depth."""
        spacing = self.depth_nodes[1] - self.depth_nodes[0]
        position = depth.clamp(min=0.0) / spacing
        index = position.detach().floor().clamp(0, self.depth_nodes.numel() - 2).long()
        return index, position - index

    def contact_weight(self, depth: torch.Tensor) -> torch.Tensor:
        """What of the first node's value holds at ``depth`` [m]: 1 in contact, falling linearly to 0 one node
        spacing before it, 0 beyond. Before contact there is no elastic force; the first node carries the
        reference's force at its contact, 0 only within the noise, and a law held there before contact put it
        under every sample that pins a contact (real agarose with 5 Pa·s added: 22 pN, 1.8 noise std, under 1450
        samples, and χ² fell by 730 where a viscosity moved the law's first node 0.1 nm: a cusp, not physics)."""
        spacing = self.depth_nodes[1] - self.depth_nodes[0]
        return (1.0 + depth / spacing).clamp(0.0, 1.0)

    def interpolate(self, node_values: torch.Tensor, depth: torch.Tensor) -> torch.Tensor:
        """Values at the depth nodes ((nodes,) or (nodes, …)) at ``depth`` [m]: linear between nodes, beyond
        the deepest continued as a line in w^1.5 (the class docstring), before contact falling to 0
        (``contact_weight``). Linear in ``node_values``."""
        index, t = self.bracket(depth)
        trailing = (...,) + (None,) * (node_values.dim() - 1)
        between = torch.lerp(node_values[index], node_values[index + 1], t[trailing])
        continued = (
            node_values[-1]
            + self.continued_slope(node_values) * (depth.clamp(min=0.0) ** 1.5 - self.deepest**1.5)[trailing]
        )
        inside = torch.where((depth > self.deepest)[trailing], continued, between)
        return inside * self.contact_weight(depth)[trailing]
