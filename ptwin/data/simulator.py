"""The forward simulator: recording sets in which chosen physics is concealed.

The cantilever base moves at constant speed v; the tip depth w obeys the force
balance k_s (z − w) = F_el(w) + g·q + F_fluid + π γ R ẇ + b·v with the terms of
shared/physics-terms.md (each absent unless named in ``effects``):

- fluid: F_D = C(w)·ẇ with C = c(H/R) μ R³ / K_eff (Darcy is linear in U), or the
  lagging F_p with τ_p dF_p/dt + F_p = F_D, τ_p = μR²/(K_eff M);
- solid_relaxation: q' = dF_el/dt − q/τ; strain_dependent_permeability: K_eff =
  K·exp(−m w/ρ); cantilever_drag: b·v on the cantilever, before contact as well;
- contact_offset: the recorded z is off by δ (depth in the model becomes w − δ).

States (w, q, F_p) are integrated by Radau (stiff: τ_p and C vanish at first contact)
from the exact contact instant. With pore relaxation and no viscous network the
balance is algebraic in w and is used differentiated (index reduction), where
C/τ_p = c·R·M stays finite as R → 0.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp

from ptwin.data.recordings import Meta
from ptwin.pgd.reference import force_coefficient
from ptwin.physics.elastic import hertz_force, hertz_stiffness
from ptwin.physics.kinematics import contact_radius

TERMS = {
    "solid_viscosity": ("gamma",),
    "solid_relaxation": ("g", "tau"),
    "pore_pressure_relaxation": ("M",),
    "strain_dependent_permeability": ("m",),
    "cantilever_drag": ("b",),
    "contact_offset": ("delta",),
}


@dataclass
class Experiment:
    """Probe, cantilever, sample and protocol of a synthetic recording set (SI units)."""

    probe_radius: float = 12.0e-6
    spring_constant: float = 2.88
    sample_thickness: float = 6.0e-3
    fluid_viscosity: float = 1.0e-3
    permeability: float = 2.0e-16
    effective_modulus: float = 2.0e4
    base_speeds: tuple[float, ...] = (0.5e-6, 2.0e-6, 8.0e-6, 40.0e-6, 80.0e-6)
    samples: int = 2000
    z_start: float = -0.2e-6
    z_end: float = 4.0e-6
    noise_std: float = 3.0e-10
    seed: int = 0
    effects: dict[str, dict[str, float]] = field(default_factory=dict)
    rtol: float = 1e-9

    def __post_init__(self):
        for term, params in self.effects.items():
            if term not in TERMS:
                raise ValueError(f"effects: unknown term {term!r}; the vocabulary is {', '.join(TERMS)}")
            missing = set(TERMS[term]) - set(params)
            if missing:
                raise ValueError(f"effects.{term}: missing parameter(s) {', '.join(sorted(missing))}")

    def param(self, term: str, name: str, default: float = 0.0) -> float:
        return float(self.effects[term][name]) if term in self.effects else default


def curve_id(speed: float) -> str:
    return f"v{speed * 1e6:g}"


def simulate_curve(experiment: Experiment, speed: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Noise-free (time, recorded z, force, true depth) of one curve at base speed ``speed``."""
    e = experiment
    rho, k, mu, H0 = e.probe_radius, e.spring_constant, e.fluid_viscosity, e.sample_thickness
    gamma = e.param("solid_viscosity", "gamma")
    g, tau = e.param("solid_relaxation", "g"), e.param("solid_relaxation", "tau", 1.0)
    modulus_m = e.param("pore_pressure_relaxation", "M", np.inf)
    m = e.param("strain_dependent_permeability", "m")
    drag = e.param("cantilever_drag", "b") * speed
    delta = e.param("contact_offset", "delta")
    lagging = "pore_pressure_relaxation" in e.effects

    time = np.linspace(0.0, (e.z_end - e.z_start) / speed, e.samples)
    z_true = e.z_start + speed * time
    contact_time = (drag / k - e.z_start) / speed  # tip reaches the surface: z − drag/k = 0

    def rates(since_contact, state):
        w, q, pore = state
        radius = contact_radius(np.array([w]), rho)[0]
        c = force_coefficient((H0 - w) / radius)
        permeability = e.permeability * np.exp(-m * w / rho)
        fluid_coefficient = c * mu * radius**3 / permeability
        stiffness = hertz_stiffness(np.array([w]), e.effective_modulus, rho)[0]
        # k(z − w) − drag with z − drag/k = v·τ exactly: no cancellation at first contact.
        unbalanced = k * (speed * since_contact - w) - hertz_force(np.array([w]), e.effective_modulus, rho)[0] - g * q
        if not lagging:
            w_rate = unbalanced / (fluid_coefficient + np.pi * gamma * radius)
            return [w_rate, stiffness * w_rate - q / tau, 0.0]
        tau_p = mu * radius**2 / (permeability * modulus_m)
        if gamma > 0:
            w_rate = (unbalanced - pore) / (np.pi * gamma * radius)
        else:
            w_rate = (k * speed + g * q / tau + pore / tau_p) / (k + (1 + g) * stiffness + c * radius * modulus_m)
        return [w_rate, stiffness * w_rate - q / tau, (fluid_coefficient * w_rate - pore) / tau_p]

    # Time since contact keeps the first, tiny steps representable. Right after contact
    # every force is negligible and the tip moves with the base: start on w = v·τ0.
    first = 1e-9 * (time[-1] - contact_time)
    after = time > contact_time + first
    solution = solve_ivp(
        rates,
        (first, time[-1] - contact_time),
        [speed * first, 0.0, 0.0],
        method="Radau",
        t_eval=time[after] - contact_time,
        rtol=e.rtol,
        atol=[1e-15, 1e-17, 1e-17],
    )
    if not solution.success:
        raise RuntimeError(f"simulation of the {curve_id(speed)} curve failed: {solution.message}")
    depth = np.minimum(z_true - drag / k, 0.0)
    depth[after] = solution.y[0]
    force = k * (z_true - depth)
    return time, z_true + delta, force, depth


def simulate(experiment: Experiment) -> tuple[Meta, pd.DataFrame]:
    """A whole recording set (meta and curves, noise added) for ``experiment``."""
    rng = np.random.default_rng(experiment.seed)
    frames = []
    for speed in experiment.base_speeds:
        time, z, force, _ = simulate_curve(experiment, speed)
        noisy = force + rng.normal(0.0, experiment.noise_std, force.size)
        frames.append(
            pd.DataFrame({"curve": curve_id(speed), "base_speed": speed, "time": time, "z": z, "force": noisy})
        )
    meta = Meta(
        probe_radius=experiment.probe_radius,
        spring_constant=experiment.spring_constant,
        sample_thickness=experiment.sample_thickness,
        fluid_viscosity=experiment.fluid_viscosity,
        reference_curve=curve_id(min(experiment.base_speeds)),
        sample="synthetic (ptwin.data.simulator)",
    )
    return meta, pd.concat(frames, ignore_index=True)
