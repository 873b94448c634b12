"""The candidate-physics vocabulary of shared/physics-terms.md as ``nn.Module`` terms.

Each term acts on the base model through one of four hooks (see ``ForceModel``):
``depth_shift`` (the depth every fluid quantity sees), ``permeability_factor``,
``lag_fluid`` (replaces F_D) and ``force`` (adds a force). Parameters are raw tensors:
log-parametrised where positivity is the physics (M, tau), plain where the sign itself
is the evidence (gamma, g, m, b, delta) — a fit that lands outside the physical range
is then *seen* and rejected by ``violation``, not hidden by a constraint.
"""

from __future__ import annotations

import math
from typing import ClassVar

import torch
from torch import nn

from ptwin.physics.recurrence import first_order_lag, relaxation_integral
from ptwin.physics.samples import Samples


class Term(nn.Module):
    """A candidate term. ``PARAMS``: physical name → (transform 'log'|'linear', default)."""

    name: ClassVar[str]
    PARAMS: ClassVar[dict[str, tuple[str, float]]]
    NON_NEGATIVE: ClassVar[tuple[str, ...]] = ()  # parameters physical only when ≥ 0
    STARTS: ClassVar[list[dict[str, float]]] = [{}]  # initial values tried by a fit

    def __init__(self, probe_radius: float, **values: float):
        super().__init__()
        self.probe_radius = probe_radius
        for name, (transform, default) in self.PARAMS.items():
            value = float(values.get(name, default))
            raw = math.log(value) if transform == "log" else value
            self.register_parameter(self.raw_name(name), nn.Parameter(torch.tensor(raw, dtype=torch.float64)))

    @classmethod
    def raw_name(cls, name: str) -> str:
        return f"log_{name}" if cls.PARAMS[name][0] == "log" else name

    def value(self, name: str) -> torch.Tensor:
        raw = getattr(self, self.raw_name(name))
        return raw.exp() if self.PARAMS[name][0] == "log" else raw

    def values(self) -> dict[str, float]:
        return {name: self.value(name).item() for name in self.PARAMS}

    def physical_std(self, raw_std: dict[str, float]) -> dict[str, float]:
        """Standard deviations of the physical values from those of the raw parameters (delta method)."""
        return {
            name: raw_std[self.raw_name(name)] * (self.value(name).item() if transform == "log" else 1.0)
            for name, (transform, _) in self.PARAMS.items()
        }

    def violation(self) -> str | None:
        """Why the fitted values are not physical, or None."""
        negative = [f"{name} < 0" for name in self.NON_NEGATIVE if self.value(name) < 0]
        return "; ".join(negative) or None

    def depth_shift(self) -> torch.Tensor | None:
        return None

    def permeability_factor(self, depth: torch.Tensor) -> torch.Tensor | None:
        return None

    def lag_fluid(self, fluid_force, samples: Samples, radius, permeability, viscosity) -> torch.Tensor | None:
        return None

    def force(self, samples: Samples, radius: torch.Tensor, elastic: torch.Tensor) -> torch.Tensor | None:
        return None


class SolidViscosity(Term):
    """Kelvin–Voigt viscous network: + π γ R U (gamma [Pa s])."""

    name = "solid_viscosity"
    PARAMS = {"gamma": ("linear", 0.0)}
    NON_NEGATIVE = ("gamma",)

    def force(self, samples, radius, elastic):
        return math.pi * self.value("gamma") * radius * samples.velocity


class SolidRelaxation(Term):
    """Standard-linear-solid network: + g ∫ exp(−(t−s)/tau) dF_el/ds ds (g [–], tau [s])."""

    name = "solid_relaxation"
    PARAMS = {"g": ("linear", 0.1), "tau": ("log", 1.0)}
    NON_NEGATIVE = ("g",)
    STARTS = [{"tau": tau} for tau in (1e-2, 1e-1, 1.0, 10.0)]

    def force(self, samples, radius, elastic):
        tau = self.value("tau").expand_as(elastic)
        return self.value("g") * relaxation_integral(elastic, tau, samples.time, samples.start)


class PorePressureRelaxation(Term):
    """Finite drainage: F_D → F_p, tau_p dF_p/dt + F_p = F_D, tau_p = μR²/(K M) (M [Pa])."""

    name = "pore_pressure_relaxation"
    PARAMS = {"M": ("log", 1.0e5)}
    STARTS = [{"M": m} for m in (1e3, 1e4, 1e5, 1e6)]

    def lag_fluid(self, fluid_force, samples, radius, permeability, viscosity):
        relaxation_time = viscosity * radius**2 / (permeability * self.value("M"))
        return first_order_lag(fluid_force, relaxation_time, samples.time, samples.start)


class StrainDependentPermeability(Term):
    """K → K·exp(−m w/ρ) (m [–])."""

    name = "strain_dependent_permeability"
    PARAMS = {"m": ("linear", 0.0)}
    NON_NEGATIVE = ("m",)

    def permeability_factor(self, depth):
        return torch.exp(-self.value("m") * depth.clamp(min=0.0) / self.probe_radius)


class CantileverDrag(Term):
    """Hydrodynamic drag on the cantilever: + b · base_speed (b [N s/m])."""

    name = "cantilever_drag"
    PARAMS = {"b": ("linear", 0.0)}
    NON_NEGATIVE = ("b",)

    def force(self, samples, radius, elastic):
        return self.value("b") * samples.base_speed


class ContactOffset(Term):
    """The recorded contact point is off by delta: the fluid sees depth w − delta (delta [m])."""

    name = "contact_offset"
    PARAMS = {"delta": ("linear", 0.0)}

    def violation(self):
        limit = self.probe_radius / 4
        return f"|delta| ≥ rho/4 = {limit:.3g} m" if abs(self.value("delta").item()) >= limit else None

    def depth_shift(self):
        return self.value("delta")


VOCABULARY: dict[str, type[Term]] = {
    cls.name: cls
    for cls in (
        SolidViscosity,
        SolidRelaxation,
        PorePressureRelaxation,
        StrainDependentPermeability,
        CantileverDrag,
        ContactOffset,
    )
}
