"""The forward simulator: recording sets in which chosen physics is concealed.

The cantilever base moves at constant speed v; the tip depth w obeys the force
balance k_s (z − w) = F_el(w) + g·q + F_fluid + π γ R ẇ + b·v with the terms of
shared/physics-terms.md (each absent unless named in ``effects``):

- fluid: F_D = C(w)·ẇ with C = c(H/R) μ R³ / K_eff (Darcy is linear in U), or the
  lagging F_p with τ_p dF_p/dt + F_p = F_D, τ_p = μR²/(K_eff M);
- solid_relaxation: q' = dF_el/dt − q/τ; strain_dependent_permeability: K_eff =
  K·exp(−m w/ρ); cantilever_drag: b·v on the cantilever, before contact as well;
- contact_offset: the recorded z is off by δ (depth in the model becomes w − δ).

F_D comes from the closed form, or from the PGD layer (``fluid_basis``), so each
checks the other. States (w, q, F_p) are integrated by Radau (stiff: τ_p and C vanish at first contact)
from the exact contact instant. With pore relaxation and no viscous network the
balance is algebraic in w and is used differentiated (index reduction), where
C/τ_p = c·R·M stays finite as R → 0.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd
import torch
from scipy.integrate import solve_ivp

from ptwin.data.kinematics import contact_radius
from ptwin.data.noise import autoregressive
from ptwin.data.recordings import APPROACH, CREEP, HOLD, SEGMENTS, Meta
from ptwin.pgd.reference import force_coefficient
from ptwin.physics.elastic import hertz_force, hertz_stiffness
from ptwin.physics.fluid_force import FluidForce
from ptwin.physics.power_law import kernel_modes
from ptwin.physics.terms import VOCABULARY

# The vocabulary terms this simulator conceals (each is integrated below), their parameters from the term classes.
SIMULATED = (
    "solid_viscosity",
    "solid_relaxation",
    "pore_pressure_relaxation",
    "power_law_rheology",
    "strain_dependent_permeability",
    "cantilever_drag",
    "contact_offset",
)
# Effects the vocabulary does not know, for benchmarks of the diagnosis's honesty:
# force_drift is an instrument drift of the recorded force, rate·t [N/s].
OUTSIDE_VOCABULARY = {"force_drift": ("rate",)}
EFFECTS = {**{name: tuple(VOCABULARY[name].PARAMS) for name in SIMULATED}, **OUTSIDE_VOCABULARY}


@dataclass(frozen=True)
class Hold:
    """A ramp-and-hold: approach until the indentation depth reaches ``depth`` [m], then the base stays
    fixed for ``seconds`` [s] (the tip keeps creeping while the force relaxes through the cantilever;
    0: an approach to that depth). ``speed``: the approach's [m/s]; None: at every base speed.
    ``creep``: a creep compliance instead: the feedback holds the force reached there for ``seconds``
    (the base follows the tip as it sinks in)."""

    depth: float
    seconds: float
    speed: float | None = None
    creep: bool = False

    @property
    def suffix(self) -> str:
        """Of the curve's id: v5h for a hold, v5c for a creep."""
        return "c" if self.creep else "h"

    @classmethod
    def proposed(cls, next_experiment: dict) -> tuple[Hold, ...]:
        """The curves a ``diagnosis.json`` ``next_experiment`` asks for (its protocol, ``repeats`` times)."""
        protocol = next_experiment["protocol"]
        approach = next(segment for segment in protocol if segment["segment"] == "approach")
        seconds = sum(segment["duration"] for segment in protocol if segment["segment"] == "hold")
        return (cls(approach["to_depth"], seconds, approach["base_speed"]),) * int(next_experiment["repeats"])


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
    fluid_basis: str | None = None  # a PGD basis file: F_D from FluidForce instead of the closed form
    # What real recordings have (off by default):
    noise_correlation: float = 0.0  # lag-1 autocorrelation of the force noise's AR(1) part
    noise_white_share: float = 0.0  # share of the noise variance that is white beside it (a white floor)
    replicates: int = 1  # curves per speed: ids v5, v5b, v5c, ...
    stiffness_spread: float = 0.0  # relative std of E* from curve to curve (each a different spot)
    contact_point: str = "known"  # "estimate": the recorded z is off by a random error per curve
    contact_error: float = 0.0  # std of that error [m]
    baseline_offset: float = 0.0  # std of a force offset per curve [N]
    tilt: float = 0.0  # baseline slope dF/dz [N/m] (virtual deflection), every curve
    sample_rate: float | None = None  # [Hz]: a curve has duration × rate samples (else ``samples``)
    holds: tuple[Hold, ...] = ()  # each: every base speed recorded again as a ramp-and-hold (ids v5h, v5h2, ...)
    # No base speeds: the ramp-and-holds alone (each with its own speed), e.g. one stress relaxation per spot.

    def __post_init__(self):
        if not self.base_speeds and (not self.holds or any(hold.speed is None for hold in self.holds)):
            raise ValueError("base_speeds: none given, so every hold needs its own speed (DEPTH:SECONDS:SPEED)")
        for term, params in self.effects.items():
            if term not in EFFECTS:
                raise ValueError(f"effects: unknown term {term!r}; known effects: {', '.join(EFFECTS)}")
            missing = set(EFFECTS[term]) - set(params)
            if missing:
                raise ValueError(f"effects.{term}: missing parameter(s) {', '.join(sorted(missing))}")

    def param(self, term: str, name: str, default: float = 0.0) -> float:
        return float(self.effects[term][name]) if term in self.effects else default

    def time(self, speed: float) -> np.ndarray:
        """Sample times of a curve at base speed ``speed`` [s]."""
        duration = (self.z_end - self.z_start) / speed
        if self.sample_rate is None:
            return np.linspace(0.0, duration, self.samples)
        return np.arange(0.0, duration, 1.0 / self.sample_rate)


def curve_id(speed: float, replicate: int = 0) -> str:
    """``v5`` for 5 µm/s; replicates ``v5b``, ``v5c``, ..."""
    return f"v{speed * 1e6:g}" + ("" if replicate == 0 else chr(ord("a") + replicate))


@dataclass
class CurveSimulation:
    """One noise-free curve: recorded z and force, true depth, and the residual of the
    force balance k_s(z − w) − F_sample − b·v at every sample [N]."""

    time: np.ndarray
    z: np.ndarray
    force: np.ndarray
    depth: np.ndarray
    balance_residual: np.ndarray
    segment: np.ndarray  # APPROACH, HOLD or CREEP
    base_speed: np.ndarray  # [m/s] per sample (0 in a hold)


def fluid_coefficient_law(experiment: Experiment):
    """C(R, H, K) = F_D/U [N s/m]: the closed form, or the PGD layer when a basis is given."""
    mu = experiment.fluid_viscosity
    if experiment.fluid_basis is None:
        return lambda radius, height, permeability: force_coefficient(height / radius) * mu * radius**3 / permeability
    layer = FluidForce.load(experiment.fluid_basis, viscosity=mu)

    def pgd(radius, height, permeability):
        with torch.no_grad():
            args = (torch.tensor(v, dtype=torch.float64).reshape(-1) for v in (1.0, radius, height, permeability))
            return layer.evaluate(*args).item()

    return pgd


# Radau's Newton iterations try states past the sample's surface (w ≤ 0), where the contact radius is 0 and the
# rates are not defined (H/R infinite, nan): it rejects those trials and shrinks its step. numpy's warnings about
# them said nothing the step control does not handle, in the middle of a user's diagnosis (the design simulates).
@np.errstate(divide="ignore", invalid="ignore", over="ignore")
def simulate_curve(
    experiment: Experiment,
    speed: float,
    effective_modulus: float | None = None,
    hold: Hold | None = None,
    balance: bool = True,
    budget: int | None = None,
) -> CurveSimulation:
    """The noise-free curve at base speed ``speed`` (on a spot of ``effective_modulus``, default the
    experiment's): an approach to ``z_end``, or, with ``hold``, an approach until the indentation depth
    reaches ``hold.depth`` and then the base fixed for ``hold.seconds``. ``balance=False`` skips the
    force balance's residual (zeros; it costs a model evaluation per sample). ``budget``: the most
    evaluations of the state equations the curve may take (a ``SimulationBudget`` error past it; None:
    no limit): what a caller trying many candidates spends on one whose values make it stiff."""
    e = replace(experiment, effective_modulus=effective_modulus or experiment.effective_modulus)
    drag = e.param("cantilever_drag", "b") * speed
    kernel = power_law_modes(e, speed, hold)
    spent = _Spent(budget)
    rates = spent.counted(_balance(e, speed, drag, kernel))
    contact_time = (drag / e.spring_constant - e.z_start) / speed  # tip reaches the surface: z − drag/k = 0
    # Time since contact keeps the first, tiny steps representable. Right after contact every force is
    # negligible and the tip moves with the base: start on w = v·τ0.
    if hold is None:
        time = e.time(speed)
        first = 1e-9 * (time[-1] - contact_time)
        after = time > contact_time + first
        states = _integrate(
            rates, (first, time[-1] - contact_time), _start(rates, speed * first), e, time[after] - contact_time
        )
        return _record(e, speed, drag, time, after, states, np.zeros(time.size, dtype=np.int64), rates, balance)
    step = float(np.diff(e.time(speed)[:2])[0])
    # As above, a billionth of the ramp; the depth w = v·τ0 must stay well above the solver's absolute
    # tolerance or its error control cannot see the stiff start.
    first = 1e-9 * (hold.depth - e.z_start) / speed
    reached = lambda since_contact, state: state[0] - hold.depth  # noqa: E731 (solve_ivp reads its attributes)
    reached.terminal, reached.direction = True, 1
    ramp = solve_ivp(
        rates,
        (first, 10.0 * (e.z_end - e.z_start) / speed),
        _start(rates, speed * first),
        method="Radau",
        rtol=e.rtol,
        atol=_tolerance(rates),
        events=reached,
        dense_output=True,
    )
    if not ramp.success or not ramp.t_events[0].size:
        raise RuntimeError(f"simulation of the {curve_id(speed)} ramp to {hold.depth:.3g} m failed: {ramp.message}")
    stop = ramp.t_events[0][0]
    # A creep holds the force recorded at the stop, the drag (on the nearly still base) in the sample's share.
    setpoint = e.spring_constant * (stop * speed - ramp.y_events[0][0][0]) + drag if hold.creep else None
    held = spent.counted(_balance(e, 0.0, drag, kernel, stop * speed, setpoint))
    fixed = solve_ivp(
        held,
        (stop, stop + max(hold.seconds, 1e-12 * stop)),
        ramp.y_events[0][0],
        method="Radau",
        rtol=e.rtol,
        atol=_tolerance(rates),
        dense_output=True,
    )
    time = np.arange(0.0, contact_time + stop + hold.seconds, step)
    since = time - contact_time
    after = since > first
    in_ramp = since[after] <= stop
    states = np.where(in_ramp, ramp.sol(np.minimum(since[after], stop)), fixed.sol(np.maximum(since[after], stop)))
    segment = np.where(since > stop, CREEP if hold.creep else HOLD, APPROACH)
    return _record(e, speed, drag, time, after, states, segment, rates, balance, held, stop, setpoint)


class SimulationBudget(RuntimeError):
    """A curve took more evaluations of its state equations than its budget."""


@dataclass
class _Spent:
    """Evaluations of the state equations of one curve, against its budget (None: none)."""

    budget: int | None
    evaluations: int = 0

    def counted(self, rates):
        if self.budget is None:
            return rates

        def counting(since_contact, state, balance=False):
            self.evaluations += 1
            if self.evaluations > self.budget:
                raise SimulationBudget(f"more than {self.budget} evaluations of the force balance")
            return rates(since_contact, state, balance)

        counting.states = rates.states
        return counting


def _balance(
    e: Experiment, speed: float, drag: float, kernel, stopped: float | None = None, setpoint: float | None = None
):
    """The state equations (w, q, F_p, q_j)' of the force balance k(z − w) = c0·F_el + Σ c_j q_j + g·q +
    F_fluid + π·γ·R·ẇ (+ b·v), in time since contact, the base moving at ``speed`` (or fixed at
    ``stopped`` past the contact, where the drag b·v has ended; or, with ``setpoint`` [N], moved by a
    feedback that holds k(z − w) there: a creep); ``kernel``: the power law's (c0, c_j, τ_j);
    ``balance=True``: the balance's residual instead [N]."""
    rho, k, mu, H0 = e.probe_radius, e.spring_constant, e.fluid_viscosity, e.sample_thickness
    gamma = e.param("solid_viscosity", "gamma")
    g, tau = e.param("solid_relaxation", "g"), e.param("solid_relaxation", "tau", 1.0)
    modulus_m = e.param("pore_pressure_relaxation", "M", np.inf)
    m = e.param("strain_dependent_permeability", "m")
    lagging = "pore_pressure_relaxation" in e.effects
    coefficient = fluid_coefficient_law(e)
    c0, weights, times = kernel
    spring = 0.0 if setpoint is not None else k  # what the balance's force changes by per unit of w (at fixed z)

    def rates(since_contact, state, balance=False):
        w, q, pore, *modes = state
        radius = contact_radius(w, rho)
        permeability = e.permeability * np.exp(-m * w / rho)
        fluid_coefficient = coefficient(radius, H0 - w, permeability)
        stiffness = hertz_stiffness(w, e.effective_modulus, rho)
        # k(z − w) − drag with z − drag/k = v·τ exactly: no cancellation at first contact.
        base = speed * since_contact if stopped is None else stopped + drag / k
        held = k * (base - w) if setpoint is None else setpoint
        unbalanced = held - c0 * hertz_force(w, e.effective_modulus, rho) - weights @ modes
        unbalanced = unbalanced - g * q
        if not lagging:
            w_rate = unbalanced / (fluid_coefficient + np.pi * gamma * radius)
            pore_rate, pore = 0.0, fluid_coefficient * w_rate
        else:
            tau_p = mu * radius**2 / (permeability * modulus_m)
            if gamma > 0:
                w_rate = (unbalanced - pore) / (np.pi * gamma * radius)
            else:
                w_rate = (spring * speed + g * q / tau + (weights / times) @ modes + pore / tau_p) / (
                    spring + (c0 + g + weights.sum()) * stiffness + fluid_coefficient / tau_p
                )
            pore_rate = (fluid_coefficient * w_rate - pore) / tau_p
        if balance:
            return unbalanced - pore - np.pi * gamma * radius * w_rate
        return [w_rate, stiffness * w_rate - q / tau, pore_rate, *(stiffness * w_rate - np.asarray(modes) / times)]

    rates.states = 3 + times.size  # w, q, F_p and one state per power-law mode
    return rates


def _start(rates, depth: float) -> list[float]:
    return [depth] + [0.0] * (rates.states - 1)


def _tolerance(rates) -> list[float]:
    return [1e-15] + [1e-17] * (rates.states - 1)


def power_law_modes(e: Experiment, speed: float, hold: Hold | None):
    """(c0, weights, relaxation times [s]) of the power-law kernel over a curve's time scales (its
    sampling step to ten times its duration); (1, [], []) without the term: Ting's integral is then F."""
    if "power_law_rheology" not in e.effects:
        return 1.0, np.zeros(0), np.ones(0)
    duration = (e.z_end - e.z_start) / speed + (hold.seconds if hold else 0.0)
    alpha = torch.tensor(e.param("power_law_rheology", "alpha"), dtype=torch.float64)
    c0, weights, times = kernel_modes(alpha, float(np.diff(e.time(speed)[:2])[0]), 10 * duration)
    return float(c0), weights.numpy(), times.numpy()


def _integrate(rates, span, start, e: Experiment, times) -> np.ndarray:
    solution = solve_ivp(rates, span, start, method="Radau", t_eval=times, rtol=e.rtol, atol=_tolerance(rates))
    if not solution.success:
        raise RuntimeError(f"simulation failed: {solution.message}")
    return solution.y


def _record(
    e, speed, drag, time, after, states, segment, rates, balance, held=None, stop=np.inf, setpoint=None
) -> CurveSimulation:
    """The recorded curve: base z, force k(z − w) (+ drift), depth, the balance residual, segments; with a
    ``setpoint`` [N], the base after ``stop`` where the feedback held the force at it (a creep)."""
    k = e.spring_constant
    contact_time = (drag / k - e.z_start) / speed
    since = time - contact_time
    z_true = e.z_start + speed * np.minimum(time, contact_time + stop)
    depth = np.minimum(z_true - np.where(since > stop, 0.0, drag) / k, 0.0)
    depth[after] = states[0]
    if setpoint is not None:
        z_true = np.where(since > stop, depth + setpoint / k, z_true)
    residual = np.zeros_like(time)
    if balance:
        residual[after] = [(rates if t <= stop else held)(t, y, balance=True) for t, y in zip(since[after], states.T)]
    drift = e.param("force_drift", "rate") * time
    delta = e.param("contact_offset", "delta")
    force = k * (z_true - depth) + drift
    speeds = np.where(segment == APPROACH, speed, 0.0)
    return CurveSimulation(time, z_true + delta, force, depth, residual, segment, speeds)


def simulate(experiment: Experiment) -> tuple[Meta, pd.DataFrame]:
    """A whole recording set (meta and curves, noise and any recording artefacts added) for ``experiment``."""
    e = experiment
    rng = np.random.default_rng(e.seed)  # the noise; the artefacts draw from their own stream
    artefacts = np.random.default_rng([e.seed, 1])
    protocols = [(speed, replicate, None, 0) for speed in e.base_speeds for replicate in range(e.replicates)]
    protocols += [
        (speed, 0, hold, number)
        for number, hold in enumerate(e.holds, start=1)
        for speed in ((hold.speed,) if hold.speed else e.base_speeds)
    ]
    frames, slowest = [], None
    for speed, replicate, hold, number in protocols:
        modulus = e.effective_modulus * (1.0 + e.stiffness_spread * artefacts.standard_normal())
        curve = simulate_curve(e, speed, modulus, hold, balance=False)  # a recording has no balance to check
        noise = correlated_noise(rng, curve.force.size, e.noise_std, e.noise_correlation, e.noise_white_share)
        travel = curve.z - curve.z[0] + e.z_start  # the true base travel from contact
        offset = e.baseline_offset * artefacts.standard_normal() + e.tilt * travel
        z = curve.z + (e.contact_error * artefacts.standard_normal() if e.contact_point == "estimate" else 0.0)
        columns = {"curve": curve_id(speed, replicate), "base_speed": curve.base_speed, "time": curve.time}
        if hold is not None:
            columns["curve"] += hold.suffix if number == 1 else f"{hold.suffix}{number}"
            columns["segment"] = np.array(SEGMENTS)[curve.segment]
        frames.append(pd.DataFrame({**columns, "z": z, "force": curve.force + offset + noise}))
        if slowest is None or speed < slowest[0]:
            slowest = (speed, columns["curve"])
    meta = Meta(
        probe_radius=e.probe_radius,
        spring_constant=e.spring_constant,
        sample_thickness=e.sample_thickness,
        fluid_viscosity=e.fluid_viscosity,
        reference_curve=slowest[1],
        sample="synthetic (ptwin.synth)",
        contact_point=e.contact_point,
    )
    curves = pd.concat(frames, ignore_index=True)
    if "segment" in curves:
        curves["segment"] = curves["segment"].fillna("approach")
        curves = curves[["curve", "base_speed", "time", "z", "force", "segment"]]
    return meta, curves


def correlated_noise(
    rng: np.random.Generator, size: int, std: float, lag1: float, white_share: float = 0.0
) -> np.ndarray:
    """Stationary noise of std ``std``: an AR(1) of lag-1 correlation ``lag1`` (white for 0) and, for a
    ``white_share`` of the variance, white noise beside it (``ptwin.data.noise``'s model: ρ_k = (1 − share)·lag1^k)."""
    white = rng.normal(0.0, std, size)
    if lag1 == 0.0:
        return white
    first = white[:1]
    rest = autoregressive(white[1:], lag1, np.sqrt(1.0 - lag1**2), first[0])
    correlated = np.concatenate([first, rest])
    if white_share == 0.0:
        return correlated
    return np.sqrt(1.0 - white_share) * correlated + np.sqrt(white_share) * rng.normal(0.0, std, size)
