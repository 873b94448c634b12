"""The rate effect before any model: F/F_ref at equal depth, and how its excess grows with speed."""

import math

import pytest

from ptwin.data.evidence import rate_effect
from ptwin.data.kinematics import curve_kinematics
from ptwin.data.recordings import load_recordings, write_recordings
from ptwin.synth.simulator import Experiment, simulate

# A stiff cantilever at three speeds on a gel too permeable for Darcy to show: the tip follows the base, so
# a power law scales the force at equal depth by (v/v_ref)^alpha exactly (Ting's integral on a ramp), and a
# Kelvin–Voigt network adds π·γ·R·v.
STIFF = dict(
    spring_constant=20.0, permeability=1e-14, base_speeds=(2e-6, 6e-6, 18e-6), samples=300, noise_std=1e-10, seed=3
)


@pytest.fixture(scope="module")
def power_law():
    """The STIFF set with a power law (alpha 0.05), simulated once for the three tests that read it (~7 s each:
    its kernel's modes make the simulator's state equations stiff and wide)."""
    return simulate(Experiment(**STIFF, effects={"power_law_rheology": {"alpha": 0.05}}))


def effect_of(tmp_path, meta, frame):
    write_recordings(tmp_path, meta, frame)
    curves = curve_kinematics(load_recordings(tmp_path))
    return rate_effect(curves, curves[0])


def test_a_power_law_scales_the_force_by_the_speed_ratio_to_the_alpha(tmp_path, power_law):
    effect = effect_of(tmp_path, *power_law)
    for profile in effect.profiles:
        assert profile.median == pytest.approx(profile.speed_ratio**0.05, abs=2e-3)
        shallow, deep = profile.ends()
        assert abs(deep - shallow) < 5e-3  # flat: a multiplicative effect
    assert "grows more slowly than linearly with speed, as a power law" in effect.sentence()


def test_a_viscous_network_adds_an_excess_that_grows_linearly_with_speed(tmp_path):
    effect = effect_of(tmp_path, *simulate(Experiment(**STIFF, effects={"solid_viscosity": {"gamma": 40.0}})))
    assert "grows linearly with speed" in effect.sentence()


def test_one_speed_ratio_says_it_cannot_tell_the_growth(tmp_path):
    write_recordings(tmp_path, *simulate(Experiment(**{**STIFF, "base_speeds": (2e-6, 6e-6)})))
    curves = curve_kinematics(load_recordings(tmp_path))
    sentence = rate_effect(curves, curves[0]).sentence()
    assert "One speed ratio cannot show" in sentence and not any(w in sentence for w in ("nan", "inf"))
    assert math.isfinite(rate_effect(curves, curves[0]).profiles[0].median)


def test_a_faster_curve_softer_than_the_reference_is_said_to_differ_by_more_than_rate(tmp_path, power_law):
    # Real agarose B: its 15 µm/s curve, from another spot, at 0.71–0.83 of the 5 µm/s one at equal depth. Here the
    # fastest of a power-law set is scaled to 80% (a spot a fifth softer): said, with its ratio; the others not.
    meta, frame = power_law[0], power_law[1].copy()
    fastest = frame["curve"] == frame["curve"].unique()[-1]
    frame.loc[fastest, "force"] *= 0.8
    write_recordings(tmp_path, meta, frame)
    curves = curve_kinematics(load_recordings(tmp_path))
    effect = rate_effect(curves, curves[0])
    softer = [p for p in effect.profiles if p.median < 1]
    assert [p.curve for p in softer] == [curves[-1].curve]
    assert softer[0].median == pytest.approx(0.8 * 9**0.05, abs=0.01)
    sentence = effect.sentence()
    assert (
        f"Faster yet softer than {curves[0].curve} (median F/F_{curves[0].curve}): {curves[-1].curve} 0.8" in sentence
    )
    assert "differ by more than rate" in sentence and curves[1].curve + " 1." not in sentence.split("Faster")[1]
    assert "Growth with speed" not in sentence  # a negative excess has no growth to read
    assert "Faster yet softer" not in effect_of(tmp_path / "clean", *power_law).sentence()
