"""Least-squares fits of a ``ForceModel``: K and the parameters of its terms.

Residuals are in units of each curve's noise floor, so ½‖r‖² is a χ²/2 and the
Bayesian information criterion compares models fitted to the same samples.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import torch
from torch.func import functional_call

from ptwin.fitting.lm import LevenbergMarquardt, ParameterVector, covariance
from ptwin.physics.model import PERMEABILITY, ForceModel
from ptwin.physics.samples import Samples
from ptwin.physics.terms import VOCABULARY


@dataclass
class PhysicsFit:
    """A fitted model on the samples ``index`` (SI values, std from the Jacobian)."""

    terms: tuple[str, ...]
    permeability: float  # [m²]
    permeability_std: float
    params: dict[str, dict[str, float]]
    param_std: dict[str, dict[str, float]]
    correlation_with_permeability: dict[str, dict[str, float]]
    violations: dict[str, str]
    chi_square: float  # ‖r‖² on the fitted samples (noise units)
    samples: int
    iterations: int
    model: ForceModel = field(repr=False)

    @property
    def parameter_count(self) -> int:
        return 1 + sum(len(p) for p in self.params.values())

    @property
    def bic(self) -> float:
        n = self.samples
        return n * math.log(self.chi_square / n) + self.parameter_count * math.log(n)

    @property
    def physical(self) -> bool:
        return not self.violations


def scaled_residual(model, samples: Samples, index: torch.Tensor):
    """θ ↦ (model − measured)/noise floor on ``index``, θ: the model's parameters that require grad."""
    vector = ParameterVector(model, [n for n, p in model.named_parameters() if p.requires_grad])
    force, noise = samples.force[index], samples.noise_floor[index]

    def residual(theta):
        predicted = functional_call(model, vector.as_dict(theta), (samples,))
        return (predicted[index] - force) / noise

    return vector, residual


def rmse(model: ForceModel, samples: Samples, index: torch.Tensor) -> float:
    """Root-mean-square of model − measured on ``index`` [N]."""
    with torch.no_grad():
        return (model(samples)[index] - samples.force[index]).square().mean().sqrt().item()


def fit_physics(model: ForceModel, samples: Samples, index: torch.Tensor, iterations: int = 60) -> PhysicsFit:
    """Fit the free parameters of ``model`` (K and its terms; frozen ones stay) to ``samples[index]`` by LM."""
    vector, residual = scaled_residual(model, samples, index)
    solver = LevenbergMarquardt(residual, vector.get())
    theta = solver.run(iterations)
    vector.set(theta)
    jacobian, r = solver.linearise(theta)
    cov = covariance(jacobian, r)
    std = cov.diagonal().clamp(min=0).sqrt()
    correlation = cov / torch.outer(std, std).clamp(min=1e-300)
    k_index = vector.names.index(PERMEABILITY)
    raw_std = dict(zip(vector.names, std.tolist()))
    raw_corr = dict(zip(vector.names, correlation[k_index].tolist()))
    permeability = model.fluid.permeability.item()
    params, param_std, corr, violations = {}, {}, {}, {}
    for name, term in model.terms.items():
        params[name] = term.values()
        raw = {p: f"terms.{name}.{term.raw_name(p)}" for p in term.PARAMS}
        param_std[name] = term.physical_std({term.raw_name(p): raw_std.get(key, 0.0) for p, key in raw.items()})
        corr[name] = {p: raw_corr.get(key, 0.0) for p, key in raw.items()}
        reason = term.violation()
        if reason:
            violations[name] = reason
    return PhysicsFit(
        terms=tuple(model.terms),
        permeability=permeability,
        permeability_std=permeability * raw_std[PERMEABILITY],
        params=params,
        param_std=param_std,
        correlation_with_permeability=corr,
        violations=violations,
        chi_square=(r @ r).item(),
        samples=int(index.numel()),
        iterations=int(solver.state["iteration"]),
        model=model,
    )


def fit_with_starts(make_model, terms: tuple[str, ...], samples: Samples, index: torch.Tensor, iterations: int = 60):
    """``fit_physics`` from the best of the terms' starting values (judged by the cost there).

    ``make_model(terms, values)`` builds a fresh ``ForceModel``.
    """
    starts = [dict(zip(terms, combo)) for combo in itertools.product(*(VOCABULARY[t].STARTS for t in terms))]
    if len(starts) == 1:
        return fit_physics(make_model(terms, starts[0]), samples, index, iterations)
    best, best_cost = None, math.inf
    for values in starts:
        model = make_model(terms, values)
        vector, residual = scaled_residual(model, samples, index)
        with torch.no_grad():
            cost = residual(vector.get()).square().sum()
        if cost < best_cost:
            best, best_cost = model, cost.item()
    return fit_physics(best, samples, index, iterations)
