"""The forward simulator against known truth."""

import numpy as np
import pytest

from ptwin.data.kinematics import contact_radius, smoothed_derivative
from ptwin.data.recordings import load_recordings, write_recordings
from ptwin.pgd.reference import force_coefficient
from ptwin.physics.elastic import hertz_force
from ptwin.synth.simulator import Experiment, simulate, simulate_curve

# scipy's numerical Jacobian overflows harmlessly on the stiff contact transient.


def fast(**changes):
    return Experiment(samples=400, base_speeds=(0.5e-6, 8e-6, 40e-6), **changes)


@pytest.mark.parametrize("speed", [8e-6, 40e-6])
def test_clean_data_give_back_the_permeability(speed):
    e = fast()
    c = simulate_curve(e, speed)
    time, z, force = c.time, c.z, c.force
    depth = z - force / e.spring_constant
    radius = contact_radius(depth, e.probe_radius)
    velocity = smoothed_derivative(time, depth, 21)
    deep = (depth > 0.5e-6) & (time < time[-12])  # the last half-window has a one-sided derivative
    fluid = force - hertz_force(depth, e.effective_modulus, e.probe_radius)
    c = force_coefficient((e.sample_thickness - depth[deep]) / radius[deep])
    apparent = c * e.fluid_viscosity * velocity[deep] * radius[deep] ** 3 / fluid[deep]
    assert np.abs(apparent / e.permeability - 1).max() < 0.01


def test_results_do_not_change_when_tolerances_tighten():
    loose = simulate_curve(fast(rtol=1e-8), 40e-6).force
    tight = simulate_curve(fast(rtol=1e-11), 40e-6).force
    assert np.abs(loose - tight).max() < 1e-5 * np.abs(tight).max()


def test_pore_relaxation_lowers_the_fast_force_only():
    base = {v: simulate_curve(fast(), v).force for v in (0.5e-6, 40e-6)}
    lag = {v: simulate_curve(fast(effects={"pore_pressure_relaxation": {"M": 3e4}}), v).force for v in (0.5e-6, 40e-6)}
    assert lag[40e-6][-1] < base[40e-6][-1] * 0.99  # 1% of ~0.8 µN: ~30x the demo noise
    assert lag[0.5e-6][-1] == pytest.approx(base[0.5e-6][-1], rel=1e-3)


def test_strain_dependent_permeability_raises_the_force_with_depth():
    reference = simulate_curve(fast(), 40e-6)
    base, depth = reference.force, reference.depth
    stiffer = simulate_curve(fast(effects={"strain_dependent_permeability": {"m": 5.0}}), 40e-6).force
    gain = stiffer - base
    assert gain[-1] > 0 and gain[-1] > gain[np.searchsorted(depth, 1e-6)] > 0


def test_drag_and_offset_leave_their_evidence():
    dragged = simulate_curve(fast(effects={"cantilever_drag": {"b": 1e-4}}), 40e-6)
    assert dragged.force[0] == pytest.approx(1e-4 * 40e-6)  # pre-contact offset grows with speed
    offset = simulate_curve(fast(effects={"contact_offset": {"delta": 0.1e-6}}), 40e-6)
    assert offset.z[0] == pytest.approx(dragged.z[0] + 0.1e-6)


@pytest.mark.parametrize(
    "effects",
    [
        {"pore_pressure_relaxation": {"M": 3e4}, "solid_relaxation": {"g": 0.3, "tau": 0.05}},
        {"pore_pressure_relaxation": {"M": 3e4}, "solid_viscosity": {"gamma": 20.0}},
        {"solid_viscosity": {"gamma": 20.0}, "strain_dependent_permeability": {"m": 3.0}},
        {"power_law_rheology": {"alpha": 0.1}, "pore_pressure_relaxation": {"M": 3e4}},
        {"power_law_rheology": {"alpha": 0.1}, "solid_relaxation": {"g": 0.3, "tau": 0.05}},
    ],
)
def test_force_balance_holds_along_the_curve_for_combined_terms(effects):
    curve = simulate_curve(fast(effects=effects), 40e-6)
    assert np.abs(curve.balance_residual).max() < 1e-6 * np.abs(curve.force).max()


def test_a_curve_without_its_balance_check_is_the_same_curve():
    """balance=False (the recordings, the design's predictions) skips the residual, nothing else."""
    effects = {"solid_relaxation": {"g": 0.3, "tau": 0.05}}
    checked = simulate_curve(fast(effects=effects), 40e-6)
    unchecked = simulate_curve(fast(effects=effects), 40e-6, balance=False)
    assert np.abs(checked.balance_residual).max() > 0
    assert not unchecked.balance_residual.any()
    np.testing.assert_array_equal(unchecked.force, checked.force)


def test_closed_form_and_pgd_fluid_forces_agree(basis_file):
    closed = simulate_curve(fast(), 40e-6).force
    pgd = simulate_curve(fast(fluid_basis=str(basis_file)), 40e-6).force
    # The test basis is a coarse 6-ring disc (discretisation ~1.6e-2 of the fluid force).
    assert np.abs(pgd - closed).max() < 1e-2 * np.abs(closed).max()


def test_generated_sets_satisfy_the_recording_contract(tmp_path):
    meta, curves = simulate(fast(noise_std=3e-10))
    write_recordings(tmp_path, meta, curves)
    loaded = load_recordings(tmp_path)
    assert loaded.curve_ids == ["v0.5", "v8", "v40"] and loaded.meta.reference_curve == "v0.5"


def test_unknown_terms_and_missing_parameters_are_refused():
    with pytest.raises(ValueError, match="unknown term 'viscosity'"):
        Experiment(effects={"viscosity": {"gamma": 1.0}})
    with pytest.raises(ValueError, match="effects.solid_relaxation: missing parameter"):
        Experiment(effects={"solid_relaxation": {"g": 0.2}})
