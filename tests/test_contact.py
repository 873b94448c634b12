"""Estimated contact points and baselines against the simulator's known recording errors."""

import math

import numpy as np
import pytest
import scipy.signal

from bench.levels_bench import kinematics
from bench.real_noise import noise_records
from ptwin.data.contact import Baseline, _line_onset, drifted, estimate_baseline, levels_with_speed
from ptwin.synth.presets import SOFT_CANTILEVER
from ptwin.synth.simulator import Experiment, simulate
from tests.conftest import needs_open_data


@pytest.mark.parametrize(("spring_constant", "tilt"), [(0.088, 5e-4), (2.88, 0.0), (0.088, -1e-3)])
def test_contact_offset_and_tilt_are_found(spring_constant, tilt):
    setting = {**SOFT_CANTILEVER, "base_speeds": (5e-6,), "noise_correlation": 0.2, "contact_error": 2e-7}
    experiment = Experiment(**{**setting, "spring_constant": spring_constant, "tilt": tilt, "baseline_offset": 3e-10})
    _, curves = simulate(experiment)
    artefacts = np.random.default_rng([0, 1])
    _, offset, error = artefacts.standard_normal(3)  # the simulator's draws: stiffness, offset, contact
    z, force = curves["z"].to_numpy(), curves["force"].to_numpy()
    baseline = estimate_baseline(z, force, spring_constant)
    assert baseline.contact_z == pytest.approx(2e-7 * error, abs=10e-9)
    assert baseline.tilt == pytest.approx(tilt, abs=5e-5)
    assert baseline.offset == pytest.approx(3e-10 * offset + tilt * (baseline.contact_z - 2e-7 * error), abs=1e-11)
    travel, corrected = baseline.remove(z, force)
    assert np.abs(corrected[travel < -0.3e-6]).mean() < 2e-11  # the baseline is gone: noise is left


def test_an_approach_that_starts_ringing_has_its_baseline_read_where_it_has_settled():
    # Public agarose approaches ring for their first 10–30% (up to 170 pN in 50-sample blocks, 12 pN after): the
    # same curve as above with a 500 pN ring of 40 samples' period, decaying over 5% of its samples, gives the same
    # contact, tilt and level (read with the ring: the level 26 pN off).
    setting = {**SOFT_CANTILEVER, "base_speeds": (5e-6,), "noise_correlation": 0.2, "contact_error": 2e-7}
    experiment = Experiment(**{**setting, "spring_constant": 0.088, "tilt": 5e-4, "baseline_offset": 3e-10})
    _, curves = simulate(experiment)
    _, offset, error = np.random.default_rng([0, 1]).standard_normal(3)
    z, force = curves["z"].to_numpy(), curves["force"].to_numpy()
    steps = np.arange(z.size)
    ring = 5e-10 * np.exp(-steps / (0.05 * z.size)) * np.sin(2 * np.pi * steps / 40.0)
    baseline = estimate_baseline(z, force + ring, 0.088)
    assert baseline.contact_z == pytest.approx(2e-7 * error, abs=10e-9)
    assert baseline.tilt == pytest.approx(5e-4, abs=5e-5)
    assert baseline.offset == pytest.approx(3e-10 * offset + 5e-4 * (baseline.contact_z - 2e-7 * error), abs=1e-11)


@pytest.mark.parametrize(("setting", "z_start"), [({}, -0.2e-6), (SOFT_CANTILEVER, -0.1e-6)])
def test_a_baseline_shorter_than_a_fifth_of_the_travel_is_read_before_the_onset(setting, z_start):
    # The demo's approach (0.2 µm of baseline, 4 µm of travel past contact) with its contact to estimate: the first
    # fifth of the travel reached 0.64 µm into contact and a line through it followed the force, so the contact was
    # read 405 nm late and a level of 24 nN (80× the noise) removed. A soft cantilever's short baseline the same.
    experiment = Experiment(
        **{**setting, "base_speeds": (5e-6,), "z_start": z_start, "contact_point": "estimate", "contact_error": 1e-7}
        | {"baseline_offset": 3e-10, "tilt": 1e-3}
    )
    _, curves = simulate(experiment)
    _, offset, error = np.random.default_rng([0, 1]).standard_normal(3)
    z, force = curves["z"].to_numpy(), curves["force"].to_numpy()
    baseline = estimate_baseline(z, force, experiment.spring_constant)
    assert baseline.contact_z == pytest.approx(1e-7 * error, abs=10e-9)
    level = 3e-10 * offset + 1e-3 * (baseline.contact_z - 1e-7 * error)
    assert baseline.offset == pytest.approx(level, abs=experiment.noise_std)


def test_the_onset_is_sought_over_the_whole_approach_and_a_snap_to_contact_leaves_the_fifth_alone():
    # A long baseline puts the onset past the middle of the approach's depths: the scan spans them all.
    experiment = Experiment(base_speeds=(5e-6,), z_start=-3e-6, contact_point="estimate", contact_error=1e-7)
    _, curves = simulate(experiment)
    _, _, error = np.random.default_rng([0, 1]).standard_normal(3)
    z, force = curves["z"].to_numpy(), curves["force"].to_numpy()
    assert _line_onset(z, force, experiment.spring_constant) == pytest.approx(1e-7 * error, abs=20e-9)
    # Like JPK approaches of afmToolkit's (72 nm of travel, a snap of −0.6 nN, then 1.5 nN in 8 nm, steeper than
    # the 0.157 N/m cantilever): no line beside a Hertz onset fits (w runs back up the rise), and the first fifth,
    # all baseline, is kept, not refused as "fewer than 10 samples before the force's onset at z = −0 m".
    z = np.linspace(0.0, 72e-9, 200)
    force = 1e-11 * np.random.default_rng(0).standard_normal(z.size) - 6e-10 * ((z > 56e-9) & (z < 64e-9))
    force += 1.5e-9 * (np.clip(z - 64e-9, 0.0, None) / 8e-9) ** 1.5
    assert _line_onset(z, force, 0.157) == math.inf
    assert 0.0 < estimate_baseline(z, force, 0.157).contact_z < 64e-9


def test_levels_are_kept_as_drag_only_where_they_rise_with_speed_beyond_free_offsets():
    # Five curves, levels σ = 0.2 nN apart from their line. Free offsets of 1 nN's spread, drawn 2000 times: how
    # often they pass for drag (one level plus b·speed within χ², b beyond t(3)'s 99%) is the stated 1% at most;
    # most draws that lie on some line are told from drag by their scatter about it. A real drag of 1e-4 N s/m
    # at these speeds (0.5–80 µm/s: 8 nN across them) is kept unless its levels fail χ² (1% of the time).
    speeds = np.array([0.5, 2.0, 8.0, 40.0, 80.0]) * 1e-6
    stds = np.full(5, 2e-10)
    rng = np.random.default_rng(3)
    offsets = [levels_with_speed(1e-9 * rng.standard_normal(5), stds, speeds) for _ in range(2000)]
    assert np.mean([fit.consistent for fit in offsets]) > 0.005  # some random offsets do lie on a line ...
    assert np.mean([fit.shows_drag for fit in offsets]) <= 0.012  # ... but do not rise beyond their scatter
    drags = [
        levels_with_speed(3e-10 + 1e-4 * speeds + 2e-10 * rng.standard_normal(5), stds, speeds) for _ in range(200)
    ]
    assert np.mean([fit.shows_drag for fit in drags]) >= 0.97


def test_levels_whose_errors_are_read_off_short_baselines_are_judged_on_f_not_on_chi_square():
    # One level plus drag (4 speeds), each level's error read off its own baseline, 7.4 effectively independent
    # samples of it (the bench-sets' p08 setting): a level over its error has Student's tails, and χ²(2)'s 99%
    # point rejected 2.8% of 4000 such sets; F(2, 7.4)'s rejects at most the stated 1%. Errors known: χ².
    speeds = np.array([1.0, 4.0, 16.0, 64.0]) * 1e-6
    rng = np.random.default_rng(5)
    error_dof = 7.4
    rejected = {math.inf: 0, error_dof: 0}
    for _ in range(4000):
        stds = 2e-10 * np.sqrt(rng.chisquare(error_dof, 4) / error_dof)
        levels = 3e-10 + 1e-4 * speeds + 2e-10 * rng.standard_normal(4)
        for read_on in rejected:
            rejected[read_on] += not levels_with_speed(levels, stds, speeds, read_on).consistent
    assert rejected[math.inf] / 4000 > 0.02 and rejected[error_dof] / 4000 <= 0.01


def test_a_drift_widens_a_level_by_what_it_moves_the_line_at_the_contact():
    # A baseline of 300 samples ending 60 before the contact, unit white noise plus a drift as long as the baseline
    # (AR(1), φ = e^(−1/300), variance 0.3): over 4000 draws the line's value at the contact scatters as ``drifted``
    # says, within the sampling error of a std (1.1%); the baseline's own error alone is 4.6 times too small.
    # Made to fail by reading the drift as white (``correlated_square`` of share 0): its error 4.0 times too small.
    n, gap, share, memory = 300, 60, 0.3, math.exp(-1.0 / 300.0)
    travel = -(np.arange(n)[::-1] + gap) * 1e-9  # [m], the contact at 0
    rng = np.random.default_rng(7)
    innovations = rng.standard_normal((4000, n)) * math.sqrt(share * (1 - memory**2))
    innovations[:, 0] = rng.standard_normal(4000) * math.sqrt(share)  # stationary from its first sample
    noise = rng.standard_normal((4000, n)) + scipy.signal.lfilter([1.0], [1.0, -memory], innovations, axis=1)
    levels = np.polynomial.polynomial.polyfit(travel, noise.T, 1)[0]  # each line's value at travel 0
    leverage = 1 / n + travel.mean() ** 2 / np.sum((travel - travel.mean()) ** 2)
    own = Baseline(0.0, 0.0, 0.0, 0.0, math.sqrt(leverage), line_sums=(n, travel.sum(), np.square(travel).sum()))
    widened = drifted(own, share, memory)
    assert widened.level_std**2 == pytest.approx(own.level_std**2 + widened.level_drift**2)
    assert abs(np.std(levels) / widened.level_std - 1) < 0.04
    assert np.std(levels) / own.level_std > 4
    assert drifted(own, 0.0, memory) == own  # no drift: the baseline as it was


@needs_open_data("PAAM hydrogel")
@needs_open_data("Agarose")
@needs_open_data("Interphase rep 2")
def test_drag_under_real_drifting_noise_stays_in_the_force(tmp_path):
    # p06's setting (four speeds, contacts estimated from 0.8 µm of baseline) with a drag of 1e-4 N s/m and windows
    # of the public cell records scaled to 0.2 nN: read each on its own baseline, the levels (0.145, 0.524, 1.48 and
    # 6.38 nN for 0.1, 0.4, 1.6 and 6.4 nN of drag, ± 0.023 nN) are not one level plus drag (χ² 25.8 on 2 degrees
    # of freedom, beyond 20.1), and the drag would go with each curve's own level. With the drift the set's slopes
    # show (0.30 σ²), each is ± 0.10 nN: one level plus drag (χ² 2.5), which stays in the force. Made to fail by
    # reading the levels without the drift: the first assertion fails.
    curves = kinematics(noise_records()["cells"], 1, 1e-4, tmp_path)
    baselines = [c.baseline for c in curves]
    assert all(b.common and b.level_drift > 0 for b in baselines)
    alone = np.sqrt([b.level_std**2 - b.level_drift**2 for b in baselines])
    levels, speeds = np.array([b.level for b in baselines]), np.array([c.base_speed for c in curves])
    assert not levels_with_speed(levels, alone, speeds).consistent


def test_the_onset_read_with_a_root_depth_force_places_the_contact_that_hertz_alone_takes_for_earlier():
    # A solid viscosity (π·γ·U·√(ρw), 5 Pa·s at 15 µm/s) grows from contact as √w, the first-order shape of a
    # contact shift: the Hertz onset puts this contact 25 nm early (26 ± 1 nm over twelve draws). Read as Hertz
    # beside a √w force, the samples before contact place it (3 nm late; 1 ± 2 nm over the twelve).
    setting = {**SOFT_CANTILEVER, "base_speeds": (15e-6,), "contact_error": 2e-7, "tilt": 0.0}
    experiment = Experiment(**setting, effects={"solid_viscosity": {"gamma": 5.0}})
    _, curves = simulate(experiment)
    _, _, error = np.random.default_rng([0, 1]).standard_normal(3)  # the simulator's draws: the contact's
    baseline = estimate_baseline(curves["z"].to_numpy(), curves["force"].to_numpy(), experiment.spring_constant)
    assert baseline.contact_z == pytest.approx(2e-7 * error - 25e-9, abs=5e-9)
    assert baseline.contact_z + baseline.root_shift == pytest.approx(2e-7 * error, abs=10e-9)
