"""The candidate-physics vocabulary of shared/physics-terms.md: one class per term, and
everything about a term on its class.

A term acts on the base model through hooks (see ``ForceModel``): ``depth_shift`` (the
depth every fluid quantity sees), ``permeability_factor``, ``lag_fluid`` (replaces F_D),
``force`` (adds a rate-dependent force) and ``elastic_force`` (a hereditary transform
of the elastic force; the self-consistent law on the reference curve then becomes a
fixed point). Parameters are raw tensors: log-parametrised where positivity is the
physics (M, tau), plain where the sign itself is the evidence (gamma, g, m, b, delta) —
a fit that lands outside the physical range is then *seen* and rejected by
``violation``, not hidden by a constraint. ``VOCABULARY`` is the registry every other
room reads (fits, selection, report, figures, simulator, configs).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import torch
from torch import nn

from ptwin.data.contact import DEPARTURE
from ptwin.physics.elastic import hertz_force
from ptwin.physics.power_law import kernel_decays, kernel_for, ting_integral
from ptwin.physics.recurrence import first_order_lag, relaxation_integral
from ptwin.physics.samples import Samples

NO_UNIT = "–"  # a dimensionless parameter's unit, as axis labels show it


@dataclass(frozen=True)
class Parameter:
    """One parameter of a term, in SI units.

    ``log``: fitted as log(value) (positivity is the physics); ``minimum``: physical only
    at or above it; ``maximum``: physical only below it; ``plausible``: the range where
    samples of the field have it. A log-parametrised value far outside that range (×/÷
    ``LIMIT``) is a limit where the term has no effect left: it reduces to the base model.
    ``absent``: the value at which the term does nothing (math.inf: as it grows without bound; None: no
    one value of this parameter removes the term).
    """

    unit: str
    default: float
    log: bool = False
    minimum: float | None = None
    maximum: float | None = None
    plausible: tuple[float, float] = (-math.inf, math.inf)
    absent: float | None = None

    LIMIT: ClassVar[float] = 1e3

    def limit(self, name: str, value: float) -> str | None:
        """'M → ∞' where a log-parametrised value has run off to a limit, else None."""
        if not self.log:
            return None
        if not math.isfinite(value) or value > self.plausible[1] * self.LIMIT:
            return f"{name} → ∞"
        if value < self.plausible[0] / self.LIMIT:
            return f"{name} → 0"
        return None

    def outside(self, name: str, value: float) -> str | None:
        """Why ``value`` is no physical value of this parameter ('gamma < 0', 'alpha ≥ 0.5'), or None."""
        if self.minimum is not None and value < self.minimum:
            return f"{name} < {self.minimum:g}"
        if self.maximum is not None and value >= self.maximum:
            return f"{name} ≥ {self.maximum:g}"
        if self.log and not value > 0:  # a value fitted in log: positivity is its physics
            return f"{name} ≤ 0"
        return None

    def raw(self, value: float) -> float:
        """``value`` as it is fitted: its log where the parameter is fitted in log."""
        return math.log(value) if self.log else value

    def allows_absence(self, interval: list[float | None]) -> bool:
        """Whether a 95% interval [low, high] (None: open on that side) reaches the value where the term does
        nothing: the data do not exclude that the term is absent."""
        low, high = interval
        if self.absent is None:
            return False
        if math.isinf(self.absent):
            return high is None
        return (low is None or low <= self.absent) and (high is None or high >= self.absent)

    def quantity(self, value: float) -> str:
        """``value`` to three digits with its unit ('7.66 Pa s'), alone where it has none ('0.518', not '0.518 –')."""
        return f"{value:.3g}" if self.unit == NO_UNIT else f"{value:.3g} {self.unit}"

    def label(self, name: str) -> str:
        """Axis label of a plot of this parameter, with its physical range."""
        below = f" (< {self.minimum:g}: non-physical)" if self.minimum is not None else ""
        return f"{name} [{self.unit}]{below}"


class Term(nn.Module):
    """A candidate term.

    Class facts: ``name`` (the contract's), ``PARAMS`` (name → ``Parameter``), ``STARTS``
    (starting values a fit tries), ``TELL_APART`` (the experiment that separates it from
    a term explaining the same residual), ``ACTS_ON_ELASTIC`` (its hook is ``elastic_force``),
    ``WITH_ESTIMATED_CONTACT`` (why it is no candidate when contact points are estimated:
    what it models is then fitted or removed as a nuisance; None if it stays one),
    ``KEPT_BY_COMMON_LEVEL`` (it stays a candidate after all where one common baseline level was
    removed from every curve: what it models is then still in the force),
    ``CONTACT_CAVEAT`` (what estimated contacts hide of it on approach curves, or None; a term with one grows
    as √w from contact, and its fits start apart, ``hidden_in_contacts``),
    ``TYPICAL`` (values samples of the field show: where ``python -m ptwin.inject`` starts its search for the
    smallest size a set could have shown, scaling the first, the term's strength),
    ``NOT_INJECTED`` (why no force added to a recording can stand for it, so ``python -m ptwin.inject`` never
    adds it; None where one can).
    """

    name: ClassVar[str]
    PARAMS: ClassVar[dict[str, Parameter]]
    STARTS: ClassVar[list[dict[str, float]]] = [{}]
    TELL_APART: ClassVar[str]
    ACTS_ON_ELASTIC: ClassVar[bool] = False
    WITH_ESTIMATED_CONTACT: ClassVar[str | None] = None
    KEPT_BY_COMMON_LEVEL: ClassVar[bool] = False
    CONTACT_CAVEAT: ClassVar[str | None] = None
    TYPICAL: ClassVar[dict[str, float]]
    NOT_INJECTED: ClassVar[str | None] = None

    def __init__(self, probe_radius: float, **values: float):
        super().__init__()
        self.probe_radius = probe_radius
        for name, parameter in self.PARAMS.items():
            raw = parameter.raw(float(values.get(name, parameter.default)))
            self.register_parameter(self.raw_name(name), nn.Parameter(torch.tensor(raw, dtype=torch.float64)))

    @classmethod
    def fluid_only(cls) -> bool:
        """Whether its hooks change the fluid force alone (no rate force, no hereditary elastic force): with the
        fluid force gone (K at the most permeable plausible material) it does nothing."""
        return cls.force is Term.force and cls.elastic_force is Term.elastic_force

    @classmethod
    def strength(cls) -> str:
        """The name of its strength, its first parameter (gamma, g, alpha, M, m, b, delta): what
        ``python -m ptwin.inject`` scales and what a size added or found is read in."""
        return next(iter(cls.PARAMS))

    @classmethod
    def raw_name(cls, name: str) -> str:
        return f"log_{name}" if cls.PARAMS[name].log else name

    def value(self, name: str) -> torch.Tensor:
        raw = getattr(self, self.raw_name(name))
        return raw.exp() if self.PARAMS[name].log else raw

    def values(self) -> dict[str, float]:
        return {name: self.value(name).item() for name in self.PARAMS}

    @classmethod
    def absent_values(cls) -> dict[str, float]:
        """Values at which the term does nothing: each parameter that can remove it at its ``absent`` value (one
        that removes it as it grows without bound: ``LIMIT``² beyond the field's range, past where a fit is read as
        run off to the limit), the others at their defaults."""
        values = {}
        for name, parameter in cls.PARAMS.items():
            absent = parameter.absent
            if absent is None:
                values[name] = parameter.default
            else:
                values[name] = parameter.plausible[1] * Parameter.LIMIT**2 if math.isinf(absent) else absent
        return values

    def physical_std(self, raw_std: dict[str, float]) -> dict[str, float]:
        """Standard deviations of the physical values from those of the raw parameters (delta method)."""
        return {
            name: raw_std[self.raw_name(name)] * (self.value(name).item() if parameter.log else 1.0)
            for name, parameter in self.PARAMS.items()
        }

    def degenerate(self) -> str | None:
        """Why the fitted values leave the term without effect ('tau → 0'), or None."""
        limits = [self.PARAMS[name].limit(name, value) for name, value in self.values().items()]
        return "; ".join(limit for limit in limits if limit) or None

    def implausible(self) -> str | None:
        """Which fitted values lie outside the range samples of the field have, or None."""
        outside = []
        for name, parameter in self.PARAMS.items():
            low, high = parameter.plausible
            value = self.value(name).item()
            if not low <= value <= high:
                outside.append(f"{name} = {parameter.quantity(value)} is outside [{low:g}, {high:g}]")
        return "; ".join(outside) or None

    def violation(self) -> str | None:
        """Why the fitted values are not physical, or None."""
        reasons = (parameter.outside(name, self.value(name).item()) for name, parameter in self.PARAMS.items())
        return "; ".join(reason for reason in reasons if reason) or None

    def law_violation(
        self, law: Callable[[float], float], modulus: Callable[[], float], noise_std: float
    ) -> str | None:
        """Why the elastic law of the model fitted with this term rules out its fitted values, or None: ``law``
        gives F_el [N] at a recorded depth [m], ``modulus()`` its Hertz E* [Pa]; ``noise_std``: the reference's [N]."""
        return None

    def depth_shift(self) -> torch.Tensor | None:
        return None

    def permeability_factor(self, depth: torch.Tensor) -> torch.Tensor | None:
        return None

    def lag_fluid(self, fluid_force, samples: Samples, radius, permeability, viscosity) -> torch.Tensor | None:
        return None

    def force(self, samples: Samples, radius: torch.Tensor) -> torch.Tensor | None:
        return None

    def elastic_force(self, samples: Samples, elastic: torch.Tensor) -> torch.Tensor | None:
        return None

    def permeability_note(self, permeability: float, viscosity: float, radius: float, duration: float) -> str | None:
        """Why, at its fitted values, this term leaves K unfixed by the recordings, or None: given K [m²], the fluid's
        viscosity [Pa s], the deepest contact radius [m] and the longest time a curve is in contact [s]."""
        return None

    def elastic_modes(self, samples: Samples) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None:
        """A hereditary term (``ACTS_ON_ELASTIC``) as exponential modes on the time scales of ``samples``:
        (extra, weights (M,), relaxation times (M,) [s]) with elastic_force(F) = extra·(F − F(0)) +
        Σ_m weights_m ∫ exp(−(t − s)/τ_m) dF/ds ds — what the self-consistent law inverts exactly."""
        return None


class SolidViscosity(Term):
    """Kelvin–Voigt viscous network: + π γ R U (gamma [Pa s])."""

    name = "solid_viscosity"
    PARAMS = {"gamma": Parameter("Pa s", 0.0, minimum=0.0, plausible=(0.0, 1e4), absent=0.0)}
    # Half-decades across the field's range: the contact corrections absorb this force at first order (the
    # caveat below), so χ² has a mirror basin at negative γ, and LM from γ 0 can fall either way (real PAAm
    # with 5 Pa·s added: to γ −6.4 from every start at 0; from these, the cost at the starts picks γ 3 and the
    # fit ends at γ 5.8).
    STARTS = [{"gamma": gamma} for gamma in (0.0, 0.3, 1.0, 3.0, 10.0, 30.0)]
    TYPICAL = {"gamma": 5.0}
    TELL_APART = "a force ∝ R·U: compare base speeds a decade apart at equal depth"
    # π·γ·R·U = π·γ·U·√(2ρw) and a contact shift δ changes a sphere's force by 2E*·√(ρw)·δ: the same √w.
    CONTACT_CAVEAT = (
        "on a sphere its force (∝ U·√w) is exactly the force of a shifted contact point, so with contact points "
        "estimated per curve it hides in them on approach curves; a hold at constant depth (U = 0) shows it"
    )

    def force(self, samples, radius):
        return math.pi * self.value("gamma") * radius * samples.velocity


class SolidRelaxation(Term):
    """Standard-linear-solid network: + g ∫ exp(−(t−s)/tau) dF_el/ds ds (g [–], tau [s])."""

    name = "solid_relaxation"
    PARAMS = {
        "g": Parameter(NO_UNIT, 0.1, minimum=0.0, plausible=(0.0, 5.0), absent=0.0),
        "tau": Parameter("s", 1.0, log=True, plausible=(1e-4, 1e4)),
    }
    STARTS = [{"tau": tau} for tau in (1e-2, 1e-1, 1.0, 10.0)]
    TYPICAL = {"g": 0.2, "tau": 0.1}
    TELL_APART = "a hold at constant depth (stress relaxation over tau)"
    ACTS_ON_ELASTIC = True

    def elastic_force(self, samples, elastic):
        tau = self.value("tau").expand_as(elastic)
        return self.value("g") * relaxation_integral(elastic, tau, samples.time, samples.start)

    def elastic_modes(self, samples):
        return torch.zeros_like(self.value("g")), self.value("g")[None], self.value("tau")[None]


class PowerLawRheology(Term):
    """Power-law network (cells, many gels): E(t) = E*·(t/t0)^(−alpha), t0 = 1 s, through Ting's hereditary
    integral of the elastic law over any base history (alpha [–], 0 ≤ alpha < 0.5)."""

    name = "power_law_rheology"
    PARAMS = {"alpha": Parameter(NO_UNIT, 0.05, minimum=0.0, maximum=0.5, plausible=(0.0, 0.5), absent=0.0)}
    STARTS = [{"alpha": alpha} for alpha in (0.02, 0.1, 0.3)]
    TYPICAL = {"alpha": 0.05}
    TELL_APART = (
        "a hold at constant depth (the force relaxes as t^(−alpha) over seconds, where Darcy's relaxes in "
        "milliseconds) or a third speed further apart (it grows as speed^alpha, Darcy's as speed)"
    )
    ACTS_ON_ELASTIC = True
    # (time, start, their kernel_decays) of the samples last seen, the tensors held so that their identity
    # cannot be another's: a fit evaluates the same samples at every step.
    _kept_decays: tuple[torch.Tensor, torch.Tensor, tuple[torch.Tensor, torch.Tensor]] | None = None

    def elastic_force(self, samples, elastic):
        return ting_integral(elastic, self.value("alpha"), samples.time, samples.start, self._decays(samples)) - elastic

    def _decays(self, samples):
        kept = self._kept_decays
        if kept is None or kept[0] is not samples.time or kept[1] is not samples.start:
            kept = self._kept_decays = (samples.time, samples.start, kernel_decays(samples.time, samples.start))
        return kept[2]

    def elastic_modes(self, samples):
        c0, weights, times = kernel_for(self.value("alpha"), samples.time)
        return c0 - 1, weights, times


UNDRAINED = 10.0  # relaxation time over the longest contact beyond which a pore pressure never drains in it


class PorePressureRelaxation(Term):
    """Finite drainage: F_D → F_p, tau_p dF_p/dt + F_p = F_D, tau_p = μR²/(K M) (M [Pa])."""

    name = "pore_pressure_relaxation"
    PARAMS = {"M": Parameter("Pa", 1.0e5, log=True, plausible=(1e2, 1e8), absent=math.inf)}
    STARTS = [{"M": m} for m in (1e3, 1e4, 1e5, 1e6)]
    TYPICAL = {"M": 3.0e4}
    TELL_APART = "a deeper indent (tau_p grows as R²) or a hold at constant depth"

    def lag_fluid(self, fluid_force, samples, radius, permeability, viscosity):
        relaxation_time = viscosity * radius**2 / (permeability * self.value("M"))
        return first_order_lag(fluid_force, relaxation_time, samples.time, samples.start)

    def permeability_note(self, permeability, viscosity, radius, duration):
        # Undrained (tau_p ≫ t): F_p ≈ (1/tau_p)∫F_D dt, and F_D ∝ μ·U·R³/K times 1/tau_p = K·M/(μR²) is M·U·R:
        # K cancels, so only a K large enough to drain within the recordings is excluded.
        relaxation_time = viscosity * radius**2 / (permeability * self.value("M").item())
        if relaxation_time < UNDRAINED * duration:
            return None
        return (
            f"{self.name}: its relaxation time μR²/(K·M) = {relaxation_time:.3g} s at the deepest contact is "
            f"{relaxation_time / duration:.0f}× the longest time a curve is in contact ({duration:.3g} s). The pore "
            "pressure never drains in these recordings, where its force no longer depends on K (it tends to M·U·R), so "
            f"they bound K from above at most; a hold of a few {relaxation_time:.2g} s would fix K"
        )


class StrainDependentPermeability(Term):
    """K → K·exp(−m w/ρ) (m [–])."""

    name = "strain_dependent_permeability"
    PARAMS = {"m": Parameter(NO_UNIT, 0.0, minimum=0.0, plausible=(0.0, 50.0), absent=0.0)}
    TYPICAL = {"m": 1.0}
    TELL_APART = "a deeper indent (the effect grows with w/rho, not with speed)"

    def permeability_factor(self, depth):
        return torch.exp(-self.value("m") * depth.clamp(min=0.0) / self.probe_radius)


class CantileverDrag(Term):
    """Hydrodynamic drag on the cantilever: + b · base_speed (b [N s/m])."""

    name = "cantilever_drag"
    PARAMS = {"b": Parameter("N s/m", 0.0, minimum=0.0, plausible=(0.0, 1e-2), absent=0.0)}
    TYPICAL = {"b": 1.0e-4}
    TELL_APART = "the approach before contact at each speed (drag offsets the baseline)"
    WITH_ESTIMATED_CONTACT = (
        "the curves' baseline levels are not one common level plus a drag that rises with speed beyond their "
        "scatter (or too few speeds to tell), so each curve's own level is removed, drag with it"
    )
    KEPT_BY_COMMON_LEVEL = True

    def force(self, samples, radius):
        return self.value("b") * samples.base_speed


class ContactOffset(Term):
    """The recorded contact point is off by delta: the fluid sees depth w − delta (delta [m])."""

    name = "contact_offset"
    PARAMS = {"delta": Parameter("m", 0.0, absent=0.0)}
    TYPICAL = {"delta": 0.1e-6}
    TELL_APART = "more pre-contact baseline and a slower first contact"
    WITH_ESTIMATED_CONTACT = "each curve's contact point is fitted as a nuisance"
    # A force added changes the fluid's force in contact and leaves the recorded onset where it was, which the
    # offset's own check reads against (``law_violation``): bench-set p01 with 293 nm added was fitted to 2.93e-7 m,
    # "puts the contact where the recording pushes 10.1 nN", rejected, and strain_dependent_permeability named weak.
    NOT_INJECTED = (
        "a contact offset moves where the recorded force starts, which a force added to the recording cannot do "
        "(the recorded onset stays, and the offset's own check rejects it there)"
    )

    def violation(self):
        limit = self.probe_radius / 4
        return f"|delta| ≥ rho/4 = {limit:.3g} m" if abs(self.value("delta").item()) >= limit else None

    def law_violation(self, law, modulus, noise_std):
        # The law is read off the reference at its recorded depths, so a contact shift common to every curve leaves
        # the elastic force as it is and only the fluid's geometry sees it: a fit can put the contact wherever the
        # rate forces like it (a drag and a viscosity concealed at known contact: 560 nm before the recorded one,
        # in a 300 nm baseline, named strong). Where contact can be is the recording's to say: before it, the
        # force is at the baseline; from it on, a solid pushes.
        delta = self.value("delta").item()
        limit = DEPARTURE * noise_std
        if delta < 0:
            excess = hertz_force(-delta, modulus(), self.probe_radius) - law(0.0)
            if excess > limit:
                return (
                    f"delta = {delta * 1e9:.3g} nm puts the contact {-delta * 1e9:.3g} nm before the recorded one, "
                    f"where a solid of the law's E* would push {excess * 1e9:.3g} nN more than the recording does"
                )
        elif (pushed := law(delta)) > limit:
            return f"delta = {delta * 1e9:.3g} nm puts the contact where the recording pushes {pushed * 1e9:.3g} nN"
        return None

    def depth_shift(self):
        return self.value("delta")


VOCABULARY: dict[str, type[Term]] = {
    cls.name: cls
    for cls in (
        SolidViscosity,
        SolidRelaxation,
        PorePressureRelaxation,
        PowerLawRheology,
        StrainDependentPermeability,
        CantileverDrag,
        ContactOffset,
    )
}


def hidden_in_contacts(terms: tuple[str, ...]) -> bool:
    """Whether one of ``terms`` grows as √w from contact (``Term.CONTACT_CAVEAT``), so that estimated contacts
    absorb its force at first order: its fits start where its shape puts the contacts (``ModelFactory``) and
    from the base model (``fit_with_starts``)."""
    return any(VOCABULARY[term].CONTACT_CAVEAT for term in terms)
