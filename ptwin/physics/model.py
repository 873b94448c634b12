"""``ForceModel``: the base model F_el(w) + F_D(U, K, R, H) plus any candidate terms,
with the self-consistent elastic law read off the reference curve."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from ptwin.physics.contact import ContactNuisance
from ptwin.physics.elastic import ReferenceCurve
from ptwin.physics.fluid_force import FluidForce, FluidInputError
from ptwin.physics.hereditary import KeptGeometry, hereditary_inverse
from ptwin.physics.samples import Samples
from ptwin.physics.terms import VOCABULARY

PERMEABILITY = "fluid.log_permeability"  # K's name among a ForceModel's parameters
# K [m²] of the soft porous materials AFM indents (dense cartilage ~1e-19, open agarose ~1e-13), with wide
# margins: a bound on K beyond them says nothing about a sample.
PLAUSIBLE_PERMEABILITY = (1e-24, 1e-9)


def fluid_off(k):
    """K [m²] within 1% of the top of ``PLAUSIBLE_PERMEABILITY``, or beyond (a float, or a tensor elementwise):
    fits start there to try a model without fluid (``physics_fit.fit_with_starts``), and a K that stays there,
    or runs past it, has no fluid force left to fix it by. Such a K is no value but that limit."""
    return k >= 0.99 * PLAUSIBLE_PERMEABILITY[1]


def smooth_contact_radius(depth: torch.Tensor, probe_radius: float) -> torch.Tensor:
    """R = sqrt(ρ² − (ρ − w)²), 0 for w ≤ 0, with finite gradients at w = 0 [m]."""
    inside = depth > 0
    w = depth.clamp(min=0.0, max=probe_radius)
    squared = (2 * probe_radius * w - w * w).where(inside, torch.ones_like(w))
    return squared.sqrt().where(inside, torch.zeros_like(w))


def total(forces: dict[str, torch.Tensor]) -> torch.Tensor:
    """The sum of the forces [N]; stacked, one op in every Jacobian's graph where Python's ``sum`` adds
    them one at a time from a constant 0."""
    return torch.stack(list(forces.values())).sum(0)


def _sample_name(samples: Samples, index: int) -> str:
    """'curve v5, sample 123' for a sample index of ``samples`` (counted within its curve)."""
    curve = int(samples.curve[index])
    first = int((samples.curve == curve).nonzero()[0])
    return f"curve {samples.curve_ids[curve]}, sample {index - first}"


class ForceModel(nn.Module):
    """Predicted force [N] of every sample: F_el(w) + F_D(U, K_eff, R, H) + terms.

    ``terms`` names vocabulary terms (``ptwin.physics.terms``); ``values`` their starting
    parameters ({term: {param: value}}). The elastic law F_el is read off ``reference``;
    self-consistent (default), it is the reference force minus this model's own
    rate-dependent forces there (F_D and every term); a term acting on the elastic force
    itself (relaxation) makes that a fixed point, iterated a few passes. With
    ``self_consistent=False`` the reference curve is taken as purely elastic (the
    paper's variant). ``probe_radius`` ρ and ``sample_thickness`` H0 [m]; K is
    ``fluid.log_permeability`` (``PERMEABILITY``). ``contact``: each curve's contact point,
    fitted as a nuisance (estimated contacts), or None (known contacts).
    """

    def __init__(
        self,
        reference: ReferenceCurve,
        fluid: FluidForce,
        probe_radius: float,
        sample_thickness: float,
        terms: Sequence[str] = (),
        values: dict[str, dict[str, float]] | None = None,
        self_consistent: bool = True,
        contact: ContactNuisance | None = None,
    ):
        super().__init__()
        values = values or {}
        unknown = set(terms) - set(VOCABULARY)
        if unknown:
            raise ValueError(f"unknown term(s) {sorted(unknown)}; the vocabulary is {', '.join(VOCABULARY)}")
        self.fluid = fluid  # first: K is then named fluid.log_permeability
        self.reference = reference
        self.probe_radius, self.sample_thickness = probe_radius, sample_thickness
        self.terms = nn.ModuleDict({n: VOCABULARY[n](probe_radius, **values.get(n, {})) for n in terms})
        self.self_consistent = self_consistent
        self.contact = contact
        self._hereditary = KeptGeometry()  # the elastic law's operator at the reference's nodes, step to step

    def fitted_name(self, term: str, name: str) -> str:
        """The name under which ``term``'s parameter ``name`` is fitted (``named_parameters``: its log's, where it is
        fitted in log)."""
        return f"terms.{term}.{self.terms[term].raw_name(name)}"

    def depth(self, samples: Samples) -> torch.Tensor:
        """The samples' depth [m], their curve's contact correction applied (estimated contacts)."""
        return samples.depth if self.contact is None else samples.depth - self.contact.shift(samples)

    def rate_forces(
        self, samples: Samples, elastic: torch.Tensor | None = None, permeability: torch.Tensor | None = None
    ) -> dict[str, torch.Tensor]:
        """The fluid force (lagged, if a term says so) and every added term's force [N].

        ``elastic``: F_el of the samples, for terms acting on it (left out when None);
        ``permeability``: K [m²] instead of the model's, one or one per sample.
        """
        forces = self._direct_forces(samples, permeability)
        return forces if elastic is None else self._with_elastic_terms(forces, samples, elastic)

    def _direct_forces(self, samples: Samples, permeability: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """The fluid force (lagged, if a term says so) and the forces of the terms not acting on F_el [N], at the
        depth from the true contact: the reference's own correction applied too (``ContactNuisance``)."""
        depth = self.depth(samples)
        if self.contact is not None:
            depth = depth - self.contact.reference
        for term in self.terms.values():
            shift = term.depth_shift()
            depth = depth if shift is None else depth - shift
        radius = smooth_contact_radius(depth, self.probe_radius)
        permeability = self.fluid.permeability if permeability is None else permeability
        for term in self.terms.values():
            factor = term.permeability_factor(depth)
            permeability = permeability if factor is None else permeability * factor
        try:
            fluid = self.fluid.evaluate(samples.velocity, radius, self.sample_thickness - depth, permeability)
        except FluidInputError as error:
            raise FluidInputError(f"{error}; {_sample_name(samples, error.point)}", error.point) from None
        for term in self.terms.values():
            lagged = term.lag_fluid(fluid, samples, radius, permeability, self.fluid.viscosity)
            fluid = fluid if lagged is None else lagged
        forces = {"fluid": fluid}
        for name, term in self.terms.items():
            added = term.force(samples, radius)
            if added is not None:
                forces[name] = added
        return forces

    def _with_elastic_terms(self, forces: dict[str, torch.Tensor], samples: Samples, elastic: torch.Tensor):
        """``forces`` (``_direct_forces``) with the forces of the terms acting on F_el, in the terms' order."""
        ordered = {"fluid": forces["fluid"]}
        for name, term in self.terms.items():
            added = forces[name] if name in forces else term.elastic_force(samples, elastic)
            if added is not None:
                ordered[name] = added
        return ordered

    def elastic_nodes(self, permeability: torch.Tensor | None = None, nodes: torch.Tensor | None = None):
        """F_el at the reference's depth nodes [N] (or at those indexed by ``nodes``, one K each:
        stage 1's pointwise K(w), defined for the base model only)."""
        if not self.self_consistent:
            return self.reference.reference_force if nodes is None else self.reference.reference_force[nodes]
        if nodes is not None and len(self.terms):
            raise ValueError("a per-node permeability is defined for the base model only (no terms)")
        at = self.reference.node_samples(nodes)
        return self._elastic_law(at, self.rate_forces(at, None, permeability))

    def _elastic_law(self, at: Samples, rate_forces: dict[str, torch.Tensor]) -> torch.Tensor:
        """F_el at the reference's node samples ``at`` [N]: the reference force less this model's rate forces
        there (``rate_forces``), the hereditary terms inverted."""
        unrelaxed = at.force - total(rate_forces)
        hereditary = [term.elastic_modes(at) for term in self.terms.values() if term.ACTS_ON_ELASTIC]
        if not hereditary:
            return unrelaxed
        # F_el + Σ hereditary(F_el) = unrelaxed on the reference's time history, solved exactly.
        extra, weights, times = (torch.cat([torch.atleast_1d(m[i]) for m in hereditary]) for i in range(3))
        return hereditary_inverse(unrelaxed, extra.sum(), weights, times, at.time, kept=self._hereditary)

    def elastic(self, depth: torch.Tensor, permeability: torch.Tensor | None = None) -> torch.Tensor:
        """F_el(depth) [N]; ``permeability``: None (the model's K) or one K [m²] per depth."""
        if permeability is None or permeability.numel() == 1:
            return self.reference.interpolate(self.elastic_nodes(permeability), depth)
        index, t = self.reference.bracket(depth)
        between = self.elastic_nodes(permeability, index) * (1 - t) + self.elastic_nodes(permeability, index + 1) * t
        return between * self.reference.contact_weight(depth)

    def law_fall(self) -> float:
        """The most the elastic law F_el falls anywhere as the depth grows [N] (0 for a monotone law). A solid
        pushes back more, not less, the deeper it is pressed: a law that falls is no solid, however well it
        fits. It also fits what it should not: with w = z − F/k_s read off the measured force, a law of
        slope s near −k_s makes the model follow the force noise itself (the residual's noise is
        −n·(1 + s/k_s)), which soft cantilevers allow."""
        with torch.no_grad():
            law = self.elastic_nodes()
            return float((torch.cummax(law, 0).values - law).max())

    def hertz_modulus(self) -> float:
        """E* [Pa] of the Hertz law F = 4/3·E*·√ρ·w^1.5 closest (least squares) to this model's elastic law."""
        with torch.no_grad():
            shape = 4.0 / 3.0 * self.probe_radius**0.5 * self.reference.depth_nodes.clamp(min=0.0) ** 1.5
            return float(shape @ self.elastic_nodes() / (shape @ shape))

    def components(self, samples: Samples, permeability: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """{'elastic': F_el, 'fluid': F_D or F_p, term name: its added force} [N], each (S,);
        ``permeability``: K [m²] instead of the model's, one or one per sample (stage 1's K(w))."""
        if permeability is not None or not self.self_consistent:
            elastic = self.elastic(self.depth(samples), permeability)
            return {"elastic": elastic, **self.rate_forces(samples, elastic, permeability)}
        # The rate forces of the samples and of the reference's depth nodes (for the elastic law) in one
        # pass: half the ops, and under autograd (a Jacobian in every fit step) ops cost more than their arithmetic.
        joined, nodes = self.reference.after(samples)
        both, count = self._direct_forces(joined), len(samples)
        law = self._elastic_law(nodes, {name: force[count:] for name, force in both.items()})
        elastic = self.reference.interpolate(law, self.depth(samples))
        direct = {name: force[:count] for name, force in both.items()}
        return {"elastic": elastic, **self._with_elastic_terms(direct, samples, elastic)}

    def forward(self, samples: Samples) -> torch.Tensor:
        return total(self.components(samples))
