"""``ForceModel``: the base model F_el(w) + F_D(U, K, R, H) plus any candidate terms."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from ptwin.physics.elastic import ReferenceElasticLaw
from ptwin.physics.fluid_force import FluidForce
from ptwin.physics.samples import Samples
from ptwin.physics.terms import VOCABULARY

RELAXATION_PASSES = 6


def smooth_contact_radius(depth: torch.Tensor, probe_radius: float) -> torch.Tensor:
    """R = sqrt(ρ² − (ρ − w)²), 0 for w ≤ 0, with finite gradients at w = 0 [m]."""
    inside = depth > 0
    w = depth.clamp(min=0.0, max=probe_radius)
    squared = (2 * probe_radius * w - w * w).where(inside, torch.ones_like(w))
    return squared.sqrt().where(inside, torch.zeros_like(w))


class ForceModel(nn.Module):
    """Predicted force [N] of every sample: F_el(w) + F_D(U, K_eff, R, H) + terms.

    ``elastic`` is the reference curve's law read without a fluid (``fluid=None``):
    ``terms`` names vocabulary terms (``ptwin.physics.terms``); ``values`` their starting
    parameters ({term: {param: value}}). Self-consistent (default): the elastic law is the
    reference curve minus this model's own rate-dependent forces there (F_D and every
    term), evaluated at its depth nodes; the solid relaxation there takes a few fixed-point
    passes (its input is the elastic force it corrects). K is ``fluid.log_permeability``.
    """

    def __init__(
        self,
        elastic: ReferenceElasticLaw,
        fluid: FluidForce,
        probe_radius: float,
        sample_thickness: float,
        terms: Sequence[str] = (),
        values: dict[str, dict[str, float]] | None = None,
        self_consistent: bool = True,
    ):
        super().__init__()
        values = values or {}
        unknown = set(terms) - set(VOCABULARY)
        if unknown:
            raise ValueError(f"unknown term(s) {sorted(unknown)}; the vocabulary is {', '.join(VOCABULARY)}")
        if elastic.fluid is not None:
            # A shared parameter would be tied under torch.func.functional_call, which loses it.
            raise ValueError(
                "ForceModel: give the elastic law without a fluid layer (fluid=None); the model "
                "subtracts its own rate-dependent forces from the reference curve"
            )
        self.fluid = fluid  # first: K is then named fluid.log_permeability
        self.elastic = elastic
        self.probe_radius, self.sample_thickness = probe_radius, sample_thickness
        self.terms = nn.ModuleDict({n: VOCABULARY[n](probe_radius, **values.get(n, {})) for n in terms})
        self.self_consistent = self_consistent

    def rate_forces(self, samples: Samples, elastic: torch.Tensor | None) -> dict[str, torch.Tensor]:
        """The fluid force (lagged, if a term says so) and every added term's force [N]."""
        depth = samples.depth
        for term in self.terms.values():
            shift = term.depth_shift()
            depth = depth if shift is None else depth - shift
        radius = smooth_contact_radius(depth, self.probe_radius)
        permeability = self.fluid.permeability
        for term in self.terms.values():
            factor = term.permeability_factor(depth)
            permeability = permeability if factor is None else permeability * factor
        fluid = self.fluid.evaluate(samples.velocity, radius, self.sample_thickness - depth, permeability)
        for term in self.terms.values():
            lagged = term.lag_fluid(fluid, samples, radius, permeability, self.fluid.viscosity)
            fluid = fluid if lagged is None else lagged
        forces = {"fluid": fluid}
        for name, term in self.terms.items():
            if elastic is None and name == "solid_relaxation":
                continue
            added = term.force(samples, radius, elastic)
            if added is not None:
                forces[name] = added
        return forces

    def elastic_nodes(self) -> torch.Tensor:
        """F_el at the elastic law's depth nodes [N]."""
        reference = self.elastic.reference_force
        if not self.self_consistent:
            return reference
        nodes = self.elastic.node_samples()
        unrelaxed = reference - sum(self.rate_forces(nodes, None).values())
        elastic = unrelaxed
        if "solid_relaxation" in self.terms:
            # F_el + g·relax(F_el) = unrelaxed: a contraction (rate ≤ g), so a few passes leave O(g⁶).
            relaxation = self.terms["solid_relaxation"]
            for _ in range(RELAXATION_PASSES):
                elastic = unrelaxed - relaxation.force(nodes, None, elastic)
        return elastic

    def components(self, samples: Samples) -> dict[str, torch.Tensor]:
        """{'elastic': F_el, 'fluid': F_D or F_p, term name: its added force} [N], each (S,)."""
        elastic = self.elastic.interpolate(self.elastic_nodes(), samples.depth)
        return {"elastic": elastic, **self.rate_forces(samples, elastic)}

    def forward(self, samples: Samples) -> torch.Tensor:
        return sum(self.components(samples).values())
