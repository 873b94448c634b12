"""Stages 1 and 2 of the paper's identification chain.

1 (§5.1): the global K of the base model (elastic + Darcy) by LM, and the apparent
  K(w) of every sample by Newton, with its plateau per curve and its trend with speed;
2 (§5.2): Gauss–Newton on (K, gamma) with the viscous term, jointly and per curve.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch

from ptwin.fitting.inflation_range import InflationRange, recorded
from ptwin.fitting.lm import FitError
from ptwin.fitting.physics_fit import PhysicsFit, fit_physics, fit_with_starts
from ptwin.fitting.pointwise import ApparentPermeability, apparent_permeability
from ptwin.physics.samples import Samples
from ptwin.physics.terms import SolidViscosity
from ptwin.pipeline.prepare import Prepared, UnsupportedSet
from ptwin.pipeline.settings import OptimSettings

VISCOUS = SolidViscosity  # the term of stage 2


@dataclass
class Identification:
    base: PhysicsFit  # stage 1, on the train split
    apparent: ApparentPermeability | None  # None: not computed (a map's spot)
    viscous: PhysicsFit | None  # stage 2, on the train split (None: the fit failed)
    viscous_per_curve: dict[str, PhysicsFit]
    viscous_term: str = VISCOUS.name
    base_range: InflationRange | None = None  # the κ² over which ``base``'s decisions go the same way


def identify(
    prepared: Prepared, optim: OptimSettings, progress: Callable[[str], None] = print, chain: bool = True
) -> Identification:
    """Stages 1 and 2 on the train split; ``chain=False``: the global K of the base model only (a map's spots:
    the diagnosis tries the viscous term among the others, and no figure shows K(w))."""
    samples, train, make_model = prepared.samples, prepared.split.train, prepared.make_model
    iterations = optim.physics_fit.iterations
    progress("stage 1: global K (elastic + Darcy) and the pointwise apparent K(w)")
    try:
        with recorded() as base_range:
            base = fit_with_starts(make_model, (), samples, train, iterations)
    except FitError as error:
        raise UnsupportedSet(
            f"{prepared.recordings.path}: the base model cannot be fitted to these curves ({error}); check the "
            f"probe radius, spring constant and sample thickness in meta.yaml"
        ) from None
    if not chain:
        return Identification(base, None, None, {}, base_range=base_range)
    p = optim.pointwise
    apparent = apparent_permeability(base.model, samples, base.permeability, p.iterations, p.plateau_from)
    progress("stage 2: Gauss–Newton on (K, gamma) with the viscous term, jointly and per speed")
    terms = (VISCOUS.name,)
    try:
        viscous = fit_physics(make_model(terms, permeability=base.permeability), samples, train, iterations)
    except FitError as error:
        progress(f"stage 2: the fit with {VISCOUS.name} failed ({error})")
        viscous = None
    per_curve = per_curve_fits(make_model, samples, train, terms, iterations)
    return Identification(base, apparent, viscous, per_curve, base_range=base_range)


def per_curve_fits(
    make_model: Callable,
    samples: Samples,
    index: torch.Tensor,
    terms: tuple[str, ...],
    iterations: int,
    free_terms: bool = True,
    values: dict | None = None,
) -> dict[str, PhysicsFit]:
    """One fit of K (and, with ``free_terms``, the terms' parameters from ``values``) per curve,
    on the samples of ``index`` in it, evaluated on that curve alone: {curve: PhysicsFit}; a curve
    whose fit fails is left out."""
    fits = {}
    for i, curve in enumerate(samples.curve_ids):
        model = make_model(terms, values)
        for term in model.terms.values():
            term.requires_grad_(free_terms)
        alone, first = samples.curve_alone(i)
        try:
            fits[curve] = fit_physics(model, alone, index[samples.curve[index] == i] - first, iterations)
        except FitError:
            continue
    return fits
