"""Ramp-and-hold physics against closed forms, the simulator's balance, and the force model."""

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

import ptwin
from ptwin.data.kinematics import curve_kinematics, segmented_derivative
from ptwin.data.recordings import APPROACH, CREEP, HOLD, load_recordings, write_recordings
from ptwin.physics.elastic import ReferenceCurve, hertz_force
from ptwin.physics.model import ForceModel, smooth_contact_radius
from ptwin.physics.recurrence import relaxation_integral
from ptwin.physics.samples import Samples
from ptwin.pipeline.prepare import UnsupportedSet, prepare
from ptwin.synth.simulator import Experiment, Hold, simulate, simulate_curve
from tests.conftest import settings_for


def test_relaxation_after_a_ramp_decays_as_the_closed_form():
    # F_el rises linearly (slope a) for T, then holds: q = a·τ(1 − e^{−T/τ})·e^{−(t−T)/τ} after it; a short
    # ramp is a step ΔF = a·T: q → ΔF·e^{−(t−T)/τ}.
    tau = 0.3
    for ramp in (0.2, 1e-4):
        time = torch.cat([torch.linspace(0, ramp, 50), torch.linspace(ramp, 3.0, 400)[1:]]).to(torch.float64)
        force = 2.0 * torch.clamp(time, max=ramp) / ramp  # ΔF = 2
        start = torch.arange(time.numel()) == 0
        q = relaxation_integral(force, torch.full_like(time, tau), time, start)
        after = time >= ramp
        expected = 2.0 / ramp * tau * (1 - math.exp(-ramp / tau)) * torch.exp(-(time[after] - ramp) / tau)
        torch.testing.assert_close(q[after], expected, rtol=1e-8, atol=1e-12)
    torch.testing.assert_close(q[after], 2.0 * torch.exp(-(time[after] - ramp) / tau), rtol=1e-3, atol=0)


def stiff_hold(effects, depth, sample_rate=20000.0, seconds=0.4):
    """A noise-free ramp-and-hold on a cantilever so stiff that the tip stays where the base stops."""
    experiment = Experiment(spring_constant=1e3, sample_rate=sample_rate, effects=effects)
    return simulate_curve(experiment, 8e-6, hold=Hold(depth, seconds)), experiment


def relaxation_time(curve) -> float:
    """τ of F(t) − F(∞) = A·e^{−t/τ} over the hold (log-linear fit where it is above 1e-3 of A; the hold
    lasts ≥ 30 τ, so F(∞) is its last value to e^{−30})."""
    hold = curve.segment == 1
    time, force = curve.time[hold], curve.force[hold]
    excess = force - force[-1]
    use = excess > 1e-3 * excess[0]
    slope = np.polyfit(time[use] - time[0], np.log(excess[use]), 1)[0]
    return -1.0 / slope


def test_pore_pressure_relaxes_with_mu_r2_over_k_m_and_scales_with_r_squared_between_depths():
    modulus = 3e4
    times, radii = [], []
    for depth in (1e-6, 3e-6):
        curve, e = stiff_hold({"pore_pressure_relaxation": {"M": modulus}}, depth)
        radius = math.sqrt(2 * e.probe_radius * depth - depth**2)
        expected = e.fluid_viscosity * radius**2 / (e.permeability * modulus)
        assert relaxation_time(curve) == pytest.approx(expected, rel=0.02)
        times.append(relaxation_time(curve))
        radii.append(radius)
    assert times[1] / times[0] == pytest.approx((radii[1] / radii[0]) ** 2, rel=0.02)


def test_the_networks_relaxation_time_does_not_change_with_depth():
    effects = {"solid_relaxation": {"g": 0.2, "tau": 0.05}}
    measured = [relaxation_time(stiff_hold(effects, depth, 2000.0, 1.6)[0]) for depth in (1e-6, 3e-6)]
    assert measured == pytest.approx([0.05, 0.05], rel=0.02)


def test_the_simulated_force_balance_holds_through_the_ramp_and_the_hold():
    for effects in ({"solid_relaxation": {"g": 0.2, "tau": 0.5}}, {"pore_pressure_relaxation": {"M": 3e4}}):
        curve = simulate_curve(Experiment(samples=400, effects=effects), 8e-6, hold=Hold(3e-6, 1.0))
        assert (curve.segment == 1).sum() > 100
        assert np.abs(curve.balance_residual).max() < 1e-6 * np.abs(curve.force).max()
        hold = curve.segment == 1
        assert curve.depth[hold][-1] > curve.depth[hold][0]  # the tip creeps while the force relaxes


def test_velocity_is_not_smeared_across_the_ramp_hold_corner():
    time = np.linspace(0, 2, 2001)
    segment = (time > 1).astype(np.int64)
    depth = np.where(segment == 0, 3e-6 * time, 3e-6)
    velocity = segmented_derivative(time, depth, 101, segment)
    np.testing.assert_allclose(velocity[segment == 0], 3e-6, rtol=1e-9)
    np.testing.assert_allclose(velocity[segment == 1], 0.0, atol=1e-15)  # rounding only: 3 µm/s before


def test_the_tips_motion_as_the_cantilever_relaxes_is_not_smeared_over_the_hold():
    # When the base stops the tip moves on for ~τ = C/(k_s + dF_el/dw) ≈ 1 ms here, carrying a Darcy force
    # of tens of nN: the hold's velocity windows grow from one sample, so they follow it (a 60-sample
    # window, the approach's, spread it over 30 ms and left 30–60 noise std of misfit there).
    experiment = Experiment(z_start=-1e-6, sample_rate=2000.0, noise_std=0.0)
    curve = simulate_curve(experiment, 10e-6, hold=Hold(3e-6, 0.2))
    velocity = segmented_derivative(curve.time, curve.depth, 60, curve.segment)
    fine = simulate_curve(replace(experiment, sample_rate=200_000.0), 10e-6, hold=Hold(3e-6, 0.2))
    true = np.interp(curve.time, fine.time, np.gradient(fine.depth, fine.time))
    hold = np.flatnonzero(curve.segment == HOLD)
    early = hold[2:20]  # 1–10 ms: the tip's motion decays from ~1 µm/s to nothing
    assert np.abs(true[hold[2]]) > 0.3e-6
    np.testing.assert_allclose(velocity[early], true[early], atol=0.1 * np.abs(true[hold[2]]))


@pytest.mark.parametrize(
    ("term", "values"),
    [
        ("solid_viscosity", {"gamma": 5.0}),
        ("solid_relaxation", {"g": 0.1, "tau": 0.5}),
        ("power_law_rheology", {"alpha": 0.05}),
        ("strain_dependent_permeability", {"m": 2.0}),
        ("cantilever_drag", {"b": 1.0e-4}),
    ],
)
def test_the_force_model_reproduces_a_simulated_hold(term, values, tmp_path, coarse_cache):
    experiment = Experiment(
        base_speeds=(0.5e-6,), holds=(Hold(3e-6, 1.0),), samples=500, noise_std=0.0, effects={term: values}
    )
    write_recordings(tmp_path, *simulate(experiment))
    reference, ramp_and_hold = curve_kinematics(load_recordings(tmp_path))
    samples = Samples.from_curves([ramp_and_hold])
    basis = next(coarse_cache.glob("*.pt"))

    def model(terms, vals):
        fluid = ptwin.FluidForce.load(basis, permeability=experiment.permeability, viscosity=1e-3)
        return ForceModel(ReferenceCurve(reference), fluid, 12e-6, 6e-3, terms, vals)

    hold = samples.in_contact & (samples.segment == 1)
    with torch.no_grad():
        error = (model((term,), {term: values})(samples) - samples.force)[hold].square().mean().sqrt()
        effect = (model((), {})(samples) - samples.force)[hold].square().mean().sqrt()
    assert effect > 3e-11  # the hold shows the term ...
    assert error < 0.1 * effect  # ... and the model with its true parameters accounts for it


@pytest.mark.parametrize(
    ("term", "values"),
    [
        ("solid_relaxation", {"g": 0.2, "tau": 0.3}),
        ("pore_pressure_relaxation", {"M": 2.0e4}),
        ("power_law_rheology", {"alpha": 0.1}),
    ],
)
def test_the_force_model_follows_a_creeps_depth_history(term, values, tmp_path, coarse_cache):
    # A creep at constant force: the feedback moves the base as the tip sinks in. The model is driven by
    # the recorded depth history, so with the true parameters it predicts the constant force; without the
    # term it does not.
    experiment = Experiment(
        base_speeds=(2e-6,),
        holds=(Hold(2e-6, 0.5, 8e-6, creep=True),),
        spring_constant=0.3,
        z_start=-0.5e-6,
        sample_rate=2000.0,
        noise_std=0.0,
        effects={term: values},
    )
    write_recordings(tmp_path, *simulate(experiment))
    reference, creep = curve_kinematics(load_recordings(tmp_path))
    samples = Samples.from_curves([creep])
    basis = next(coarse_cache.glob("*.pt"))
    fluid = ptwin.FluidForce.load(basis, permeability=experiment.permeability, viscosity=1e-3)
    model = ForceModel(ReferenceCurve(reference), fluid, 12e-6, 6e-3, (term,), {term: values})
    base = ForceModel(ReferenceCurve(reference), fluid, 12e-6, 6e-3)
    crept = samples.in_contact & (samples.segment == CREEP)
    assert np.ptp(creep.depth[creep.segment == CREEP]) > 0.02e-6  # the tip sinks in ...
    with torch.no_grad():
        error = (model(samples) - samples.force)[crept].square().mean().sqrt()
        effect = (base(samples) - samples.force)[crept].square().mean().sqrt()
    assert effect > 1e-10  # ... the creep shows the term ...
    assert error < 0.1 * effect  # ... and the model with its true parameters accounts for it


def test_holds_through_the_contact_radius_stay_finite_at_zero_depth():
    radius = smooth_contact_radius(torch.tensor([-1e-9, 0.0, 1e-9], dtype=torch.float64), 12e-6)
    assert torch.isfinite(radius).all() and radius[0] == 0


def test_a_slow_ramp_reaches_its_hold_depth_when_the_quasi_static_balance_says():
    """A slow approach on a stiff cantilever: the tip starts a billionth of the ramp into the sample. Started
    a billionth of one sampling step in (far below the solver's tolerance), its error control missed the stiff
    start and the hold began after 40 µs, at the wrong depth."""
    # The values of an experiment-design candidate that once failed.
    e = Experiment(
        probe_radius=12e-6,
        spring_constant=2.88,
        effective_modulus=19998.68479659364,
        permeability=1.989112236492037e-16,
        samples=2000,
        z_start=-2e-7,
        z_end=7.777260552219547e-06,
        sample_rate=1902.8571428570954,
        base_speeds=(1.6666666666666665e-07,),
    )
    depth, speed = 3.3886302761097735e-06, 1.6666666666666665e-07
    curve = simulate_curve(e, speed, hold=Hold(depth, 0.0), balance=False)
    force = hertz_force(np.array([depth]), e.effective_modulus, e.probe_radius)[0]
    quasi_static = (depth + force / e.spring_constant - e.z_start) / speed  # base at k(z − w) = Hertz(w)
    assert curve.time[-1] == pytest.approx(quasi_static, rel=0.01)
    assert curve.depth[-1] == pytest.approx(depth, rel=1e-3)


def test_holds_at_the_references_depth_are_fitted_and_one_approach_alone_is_refused(tmp_path, coarse_cache):
    # Two ramp-and-holds to the same depth: the tip creeps on in each hold (the force relaxes through the
    # cantilever), beyond the reference's deepest approach sample. Both holds are fitted (the reference's
    # own too: its approach is the law); with one approach and no hold the set is refused in one line.
    holds = (Hold(2e-6, 0.3, 2e-6), Hold(2e-6, 0.3, 8e-6))
    experiment = Experiment(base_speeds=(), holds=holds, spring_constant=0.5, samples=600, noise_std=1e-10)
    write_recordings(tmp_path / "holds", *simulate(experiment))
    prepared = prepare(
        settings_for(f"data.path={tmp_path / 'holds'}", "pgd=coarse", f"cache_dir={coarse_cache}"), lambda s: None
    )
    samples, law = prepared.samples, prepared.make_model.reference
    assert samples.curve_ids == ("v2h", "v8h2")
    unresolved = torch.from_numpy(np.concatenate([curve.unresolved for curve in prepared.fitted]))
    for curve in range(2):
        hold = (samples.curve == curve) & (samples.segment == HOLD)
        assert (samples.depth[hold] > law.deepest).all()  # the whole hold lies beyond the law read off v2h ...
        # ... and is fitted, but for where the stop outruns the sampling (its first sample or two)
        assert samples.in_contact[hold & ~unresolved].all()
        assert unresolved[hold].sum() <= 2
    assert not samples.in_contact[(samples.curve == 0) & (samples.segment == APPROACH)].any()

    write_recordings(tmp_path / "one", *simulate(Experiment(base_speeds=(5e-6,), samples=300)))
    with pytest.raises(UnsupportedSet, match="every curve is at 5 µm/s; .* or hold the base still"):
        prepare(
            settings_for(f"data.path={tmp_path / 'one'}", "pgd=coarse", f"cache_dir={coarse_cache}"), lambda s: None
        )
