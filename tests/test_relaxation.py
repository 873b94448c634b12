"""What a hold shows before any model (``ptwin.data.relaxation``), against a known relaxation."""

import math
from dataclasses import replace

import pytest

from ptwin.data.kinematics import contact_radius, curve_kinematics
from ptwin.data.recordings import load_recordings, write_recordings
from ptwin.data.relaxation import relaxations
from ptwin.pgd.reference import force_coefficient
from ptwin.synth.simulator import Experiment, Hold, simulate


def held(tmp_path, effects, speed=20e-6, **experiment):
    experiment = Experiment(
        base_speeds=(),
        holds=(Hold(2e-6, 2.0, speed),),
        spring_constant=1e3,  # the tip stays where the base stops: the force relaxes at constant depth
        z_start=-1e-6,
        sample_rate=5000.0,
        noise_std=1e-10,
        effects=effects,
        **experiment,
    )
    write_recordings(tmp_path, *simulate(experiment))
    return relaxations(curve_kinematics(load_recordings(tmp_path)))


def test_a_single_exponential_relaxes_half_way_at_tau_ln_2(tmp_path):
    tau = 0.1  # so permeable a gel that its Darcy force is below the noise: the network alone relaxes
    (hold,) = held(tmp_path, {"solid_relaxation": {"g": 0.3, "tau": tau}}, permeability=1e-13)
    assert hold.kind == "hold" and hold.seen and hold.duration == pytest.approx(2.0, abs=1e-3)
    assert 0.05 < hold.change < 0.3
    assert hold.half_time == pytest.approx(tau * math.log(2), abs=2e-3)  # 10 samples at 5 kHz
    assert f"half of it in the first {hold.half_time:.3g} s" in hold.sentence()


def test_an_elastic_hold_relaxes_by_the_darcy_force_at_once(tmp_path):
    # Without a relaxing term the Darcy force c·μ·U·R³/K is all that goes when the base stops, at once.
    (hold,) = held(tmp_path, {})
    e, depth = Experiment(), 2e-6
    radius = contact_radius(depth, e.probe_radius)
    darcy = force_coefficient((e.sample_thickness - depth) / radius) * 1e-3 * 20e-6 * radius**3 / e.permeability
    assert hold.start - hold.end == pytest.approx(darcy, rel=0.02)
    assert hold.half_time < 5 / 5000.0  # within the first samples


def test_a_hold_without_any_change_is_said_to_show_none(tmp_path):
    (hold,) = held(tmp_path, {}, permeability=1e-13)  # the Darcy force below the noise
    assert not hold.seen and hold.half_time is None
    assert "within 3 standard errors of none" in hold.sentence()


def test_a_held_force_that_ends_below_the_baseline_is_not_read_as_a_relaxed_fraction():
    # The real JPK stress relaxation of a cell (afmformats' test data): the baseline read off its approach, a tilt
    # extended 11 µm into contact, left the hold relaxing from 108.8 to −97.9 nN, "by 190%". No tip pulls there.
    from ptwin.data.relaxation import Relaxation

    wrong = Relaxation("v20h", "hold", 30.0, 108.8e-9, -97.9e-9, 1e-9, 1.6)
    assert "ends below the baseline" in wrong.sentence() and "not a measurement" in wrong.sentence()
    right = Relaxation("v20h", "hold", 30.0, 324e-9, 116e-9, 1e-9, 1.6)
    assert right.sentence().startswith("v20h: the force relaxes by 64.2% over the 30 s hold")


def test_a_creep_says_its_force_as_recorded_rather_than_held(tmp_path):
    # A creep's sentence said "at constant force" whatever the force did: a hold marked creep, relaxing 12%, read so.
    creep = Hold(2e-6, 0.5, 8e-6, creep=True)
    experiment = Experiment(base_speeds=(), holds=(creep,), z_start=-0.5e-6, sample_rate=2000.0, noise_std=1e-10)
    write_recordings(tmp_path, *simulate(replace(experiment, effects={"solid_relaxation": {"g": 0.2, "tau": 0.1}})))
    (crept,) = relaxations(curve_kinematics(load_recordings(tmp_path)))
    first, last = crept.force
    assert crept.kind == "creep" and last == pytest.approx(first, rel=0.01)  # the simulated feedback holds it
    assert f"creep (its force {first * 1e9:.4g} → {last * 1e9:.4g} nN, " in crept.sentence()
    assert "constant force" not in crept.sentence()
