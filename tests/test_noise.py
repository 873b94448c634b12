"""The noise model against known truth: white + AR(1) noise of given std and correlation."""

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
import scipy.signal
import scipy.stats

from ptwin.data.kinematics import curve_kinematics
from ptwin.data.noise import (
    BASELINE,
    SECOND_DIFFERENCES,
    SHORT_BASELINES,
    ar1_inflation,
    autoregressive,
    baseline_noise,
    block_inflation,
    corrected,
    curve_noise,
    detrended_lag_sums,
    level_settled,
    mean_inflation,
    model_inflation,
    pooled,
    residual_noise,
    settled,
    slope_variance,
    trend_basis,
    with_std,
)
from ptwin.data.recordings import RecordingError, load_recordings, write_recordings
from ptwin.data.tails import chi_square_exceeded, fisher_exceeded, normal_exceeded, student_t_exceeded
from ptwin.pipeline.prepare import prepare
from ptwin.synth.simulator import Experiment, correlated_noise, simulate
from tests.conftest import OPEN_DATA, needs_open_data, settings_for, simulated_set


def ar1(lag1, size=20000, std=1.3e-11, seed=0):
    return correlated_noise(np.random.default_rng(seed), size, std, lag1)


def mixed(rng, size, correlation_samples, white_share):
    """Unit-variance noise: a white part and an AR(1) part of the given correlation time (samples)."""
    return correlated_noise(rng, size, 1.0, np.exp(-1.0 / correlation_samples), white_share)


@pytest.mark.parametrize("memory", [0.0, 0.5, 0.99])
def test_the_autoregressive_filter_is_scipys_to_the_bit(memory):
    rng = np.random.default_rng(4)
    inputs, before, gain = rng.standard_normal((700, 30)), rng.standard_normal(30), np.sqrt(1.0 - memory**2)
    scipys = scipy.signal.lfilter([gain], [1.0, -memory], inputs, axis=0, zi=memory * before[None, :])[0]
    assert np.array_equal(autoregressive(inputs, memory, gain, before), scipys)
    memories = np.array([0.0, 0.3, 0.95])  # one filter per φ, broadcast along a new last axis
    each = np.stack([scipy.signal.lfilter([1.0], [1.0, -m], inputs, axis=0) for m in memories], axis=2)
    assert np.array_equal(autoregressive(inputs[:, :, None], memories), each)
    one = scipy.signal.lfilter([gain], [1.0, -memory], inputs[:, 0], zi=[memory * before[0]])[0]  # a single record
    assert np.array_equal(autoregressive(inputs[:, 0], memory, gain, before[0]), one)
    assert autoregressive(inputs[:0], memory).shape == (0, 30)  # an empty record, as lfilter takes it
    assert autoregressive(inputs[:0, 0], memory).shape == (0,)


@pytest.mark.parametrize("probability", [0.5, 0.01, 1e-4])
def test_the_tail_quantiles_are_scipy_stats_to_the_bit(probability):
    assert chi_square_exceeded(probability, 3) == scipy.stats.chi2.ppf(1.0 - probability, 3)
    assert chi_square_exceeded(probability, 7.5) == scipy.stats.chi2.ppf(1.0 - probability, 7.5)
    assert student_t_exceeded(probability, 4) == scipy.stats.t.ppf(1.0 - probability, 4)
    assert fisher_exceeded(probability, 2, 37.5) == scipy.stats.f.ppf(1.0 - probability, 2, 37.5)
    assert normal_exceeded(probability) == scipy.stats.norm.isf(probability)


def test_simulated_noise_with_a_white_floor_has_the_noise_models_autocorrelation():
    # ρ_k = (1 − share)·φ^k: what ``ptwin.data.noise`` fits and the bench-sets' AR(1) noise with a white floor has.
    noise = correlated_noise(np.random.default_rng(3), 400_000, 2.0, 0.95, white_share=0.4)
    assert noise.std() == pytest.approx(2.0, rel=0.02)
    for lag in (1, 5, 20):
        measured = np.corrcoef(noise[:-lag], noise[lag:])[0, 1]
        assert measured == pytest.approx(0.6 * 0.95**lag, abs=0.01)


def detrended(values):
    index = np.arange(values.size)
    return values - np.polyval(np.polyfit(index, values, 1), index)


@pytest.mark.parametrize("degree", [1, 6])
def test_the_expected_autocorrelation_of_a_detrended_record_is_what_records_show(degree):
    # Closed form (diagonal sums of M·T·M) against 4000 simulated 60-sample records of AR(1) noise, φ = 0.9:
    # removing a line (or a polynomial of degree 6: the residual in contact of a map's spot) takes most of the
    # correlation out of a record this short, and the formula says how much.
    rng = np.random.default_rng(3)
    basis = trend_basis(60, degree)
    records = [(r := correlated_noise(rng, 60, 1.0, 0.9)) - basis @ (basis.T @ r) for _ in range(4000)]
    simulated = [np.mean([np.sum(r[: 60 - k] * r[k:]) for r in records]) for k in range(6)]
    expected = detrended_lag_sums(60, 0.9, 5, degree)
    assert expected == pytest.approx(simulated, rel=0.06, abs=0.3)
    assert expected[0] < 0.8 * 60  # the naive expectation (60·φ^0) is far off
    # white: n less the polynomial's parameters
    assert detrended_lag_sums(60, 0.0, 0, degree)[0] == pytest.approx(60.0 - degree - 1)
    if degree == 1:  # the line of a baseline in z, removed by least squares, is the same projection
        assert records[0] == pytest.approx(detrended(records[0] + basis @ np.ones(2)), abs=1e-12)


def test_a_std_read_off_second_differences_is_corrected_for_the_sets_correlation():
    # AR(1) noise of ρ₁ 0.9 with no baseline to measure it on (a map's spot: 36 samples before contact): second
    # differences read σ 3.8× low; every residual was then 3.8 σ, and the diagnosis's statistics 14× too large.
    time = np.linspace(0, 1, 4000)
    force = 5e-7 * time**1.5 + ar1(0.9, 4000, 3e-10)
    raw = curve_noise(time, time - 0.01, force, time < 0.01, block=50)
    assert raw.std == pytest.approx(3e-10 / 3.8, rel=0.15)
    correlation = replace(raw, share=1.0, memory=0.9, source=BASELINE)
    assert corrected(raw, correlation).std == pytest.approx(3e-10, rel=0.1)
    # a correlation read off short baselines alone corrects nothing: too uncertain for it
    assert corrected(raw, replace(correlation, source=SHORT_BASELINES)).std == raw.std
    assert corrected(corrected(raw, correlation), correlation).std == corrected(raw, correlation).std  # once
    given = with_std(raw, 3e-10, "noise_std of meta.yaml")  # a lab's σ is not read off differences
    assert corrected(given, correlation).std == 3e-10


def test_short_baselines_together_give_the_inflation_their_records_alone_would_underestimate():
    # Eight baselines of 150 samples of noise 40% white, 60% AR(1) of 20 samples (the shared AR sets' noise):
    # the lag-1 correlation alone (an AR(1) summary) predicts κ² ≈ 3.5; the truth at 50-sample blocks is 15.6.
    truth = model_inflation(0.6, np.exp(-1 / 20), 50)
    estimates = []
    for seed in range(5):
        rng = np.random.default_rng(seed)
        time, z = np.arange(150) / 2000.0, np.linspace(-1e-6, -0.2e-6, 150)
        curves = [baseline_noise(time, z, 1e-10 * mixed(rng, 150, 20, 0.4), 50) for _ in range(8)]
        estimates.append(pooled(curves, [1] * 8, [5e-4] * 8, 50).inflation)
    assert np.median(estimates) == pytest.approx(truth, rel=0.35)
    assert min(estimates) > 2 * ar1_inflation(0.6 * np.exp(-1 / 20), 50)


@pytest.mark.parametrize("lag1", [0.0, 0.3, 0.7])
def test_baseline_noise_recovers_std_correlation_and_block_inflation(lag1):
    time = np.arange(20000) / 2000.0
    z = np.linspace(-2e-6, -0.5e-6, 20000)
    force = ar1(lag1) + 3e-10 + 4e-4 * z  # an offset and a tilt: not noise
    model = baseline_noise(time, z, force, block=50)
    assert model.source == BASELINE
    assert model.std == pytest.approx(1.3e-11, rel=0.03, abs=0)
    assert model.lag1 == pytest.approx(lag1, abs=0.03)
    assert model.inflation == pytest.approx(ar1_inflation(lag1, 50), rel=0.15)
    expected_time = -(np.log(lag1) ** -1) / 2000.0 if lag1 else 0.0
    assert model.correlation_time == pytest.approx(expected_time, rel=0.15)


def test_ar1_inflation_is_the_variance_of_block_means():
    # Closed form against brute force: the variance of means of 50 samples of AR(1) noise.
    noise = ar1(0.5, size=400000, std=1.0, seed=1)
    means = noise[: 400000 // 50 * 50].reshape(-1, 50).mean(axis=1)
    assert 50 * means.var() == pytest.approx(ar1_inflation(0.5, 50), rel=0.05)
    assert ar1_inflation(0.0, 50) == 1.0


def test_without_a_baseline_the_std_comes_from_second_differences_and_white_is_assumed():
    time = np.linspace(0, 1, 4000)
    force = 5e-7 * time**1.5 + ar1(0.0, 4000, 3e-10)
    model = curve_noise(time, time - 0.01, force, time < 0.01, block=50)  # 40 baseline samples: too few
    assert model.source == SECOND_DIFFERENCES
    assert model.std == pytest.approx(3e-10, rel=0.08, abs=0)
    assert model.inflation == 1.0


def test_the_set_pools_correlation_from_the_curves_that_measured_it():
    time = np.arange(3000) / 2000.0
    z = np.linspace(-2e-6, -0.5e-6, 3000)
    measured = [baseline_noise(time, z, ar1(0.4, 3000, seed=s), 50) for s in range(3)]
    guessed = curve_noise(time, z, ar1(0.4, 3000, seed=9), np.zeros(3000, bool), 50)  # the same instrument
    set_noise = pooled([*measured, guessed], [1, 1, 1, 1], [5e-4] * 4)
    assert set_noise.source == BASELINE
    assert set_noise.inflation == pytest.approx(ar1_inflation(0.4, 50), rel=0.15)
    assert set_noise.blocks == pytest.approx(3 * 3000 / 50)
    # The curve without a baseline: σ from second differences, corrected for the set's correlation
    # (they read σ·√(1 − φ) of AR(1) noise: ~23% low at φ = 0.4, so the set's σ would be ~6% low).
    assert set_noise.std == pytest.approx(1.3e-11, rel=0.04, abs=0)


def test_the_set_says_the_longest_record_its_correlation_was_read_on():
    # A record sees the noise at scales up to its own length (``words._slower_than_measured`` reads it).
    lengths = (1200, 600, 300)
    time, z = np.arange(1200) / 2000.0, np.linspace(-2e-6, -0.5e-6, 1200)
    measured = [baseline_noise(time[:n], z[:n], ar1(0.4, n, seed=n), 50) for n in lengths]
    assert pooled(measured, [1, 1, 1], [5e-4] * 3).longest == max(m.record.size for m in measured) > 1100
    residual = residual_noise([ar1(0.4, n, seed=n) for n in (900, 2500)], 1e-11, 5e-4, 50)
    assert residual.longest == 2500
    assert curve_noise(time, z, ar1(0.0, 1200), time < 0.01, 50).longest == 0  # none: second differences


def test_a_noise_std_written_in_meta_yaml_replaces_sigma_and_keeps_the_measured_correlation(tmp_path):
    experiment = Experiment(samples=1500, z_start=-1.0e-6, noise_correlation=0.6, noise_std=2.5e-10)
    meta, curves = simulate(experiment)
    write_recordings(tmp_path, replace(meta, noise_std=3.0e-10), curves)
    kinematics = curve_kinematics(load_recordings(tmp_path))
    noise = pooled([c.noise for c in kinematics], [1] * len(kinematics), [1e-3] * len(kinematics))
    assert noise.std == 3.0e-10
    assert "meta.yaml" in noise.source and BASELINE in noise.source
    assert noise.inflation == pytest.approx(ar1_inflation(0.6, 50), rel=0.25)


def test_the_correlation_of_a_residual_in_contact_is_the_noises_where_the_baselines_are_short():
    # Three curves' residuals after a flexible model: AR(1) noise of 20-sample memory (40% white, the shared
    # p07's) plus what the model left, a slow wiggle of a tenth of the noise. Read off them, κ² at 50-sample blocks
    # is the noise's (15.6), not the 40 its short baselines gave a perturbed p07, and rests on ν = 90 blocks.
    from ptwin.data.noise import RESIDUAL, SHORT_BASELINES, residual_noise, rests_on_short_records

    rng = np.random.default_rng(4)
    wiggle = 0.1 * np.sin(np.linspace(0, 6, 1500))
    records = [2.5e-10 * (mixed(rng, 1500, 20.0, 0.4) + wiggle) for _ in range(3)]
    noise = residual_noise(records, 2.5e-10, 1e-3, 50)
    truth = model_inflation(0.6, np.exp(-1 / 20), 50)
    assert noise.inflation == pytest.approx(truth, rel=0.3)
    assert noise.std == 2.5e-10 and noise.source == RESIDUAL and noise.blocks == pytest.approx(90)
    assert residual_noise([records[0][:80]], 2.5e-10, 1e-3, 50) is None  # no record long enough
    assert rests_on_short_records(replace(noise, source=f"std from noise_std; correlation from the {SHORT_BASELINES}"))
    assert not rests_on_short_records(replace(noise, source=BASELINE))


def test_a_baseline_whose_approach_starts_ringing_is_measured_where_it_has_settled():
    # Public agarose curves ring as the approach starts (40–170 pN over the first 10–30% of the travel, 12 pN
    # after it). A 12 pN noise under a 150 pN ring decaying in 150 samples: the first 400 samples are left out and
    # σ is read within 5% (all of it: twice too large); a stationary record loses nothing, nor one with a burst later.
    rng = np.random.default_rng(4)
    size, std = 2000, 1.2e-11
    time, z = np.arange(size) / 5000.0, np.linspace(-2e-6, -0.5e-6, size)
    ring = 1.5e-10 * np.exp(-np.arange(size) / 150.0) * np.sin(2 * np.pi * np.arange(size) / 40.0)
    noise = std * rng.standard_normal(size)
    assert 250 <= settled(noise + ring, 50) <= 600
    ringing = baseline_noise(time, z, noise + ring, 50)
    assert ringing.std == pytest.approx(std, rel=0.05) and ringing.unsettled == settled(noise + ring, 50)
    assert np.std(noise + ring) > 1.9 * std
    burst = noise.copy()
    burst[1000:1100] *= 10.0
    assert settled(noise, 50) == settled(burst, 50) == 0


def test_a_baseline_whose_approach_starts_off_its_level_is_measured_where_it_has_settled():
    # Public PAAm curves: the first 10–20 ms of an approach sit 16–26 pN off the baseline's line, under 13 pN of
    # near-white noise. Here 25 pN over the first 50 samples of 1000: they are left out, and the noise is what the
    # rest alone gives; left in, that one block mean, 14 standard errors off, would read as memory (κ² measured on
    # the block means more than doubles).
    rng = np.random.default_rng(6)
    size, std = 1000, 1.3e-11
    time, z = np.arange(size) / 5000.0, np.linspace(-3e-6, -1e-6, size)
    for _ in range(20):
        noise = std * rng.standard_normal(size)
        shifted = noise + np.where(np.arange(size) < 50, 2.5e-11, 0.0)
        start = level_settled(z, shifted, 50)  # a block after it can depart beyond the ceiling too, by chance
        assert 50 <= start <= 100 and level_settled(z, noise, 50) == 0
        measured = baseline_noise(time, z, shifted, 50)
        assert replace(measured, unsettled=0) == baseline_noise(time[start:], z[start:], shifted[start:], 50)
        assert measured.unsettled == start
        left_in, clean = (f - np.polyval(np.polyfit(z, f, 1), z) for f in (shifted, noise))
        assert block_inflation(left_in, 50) > 2.0 * block_inflation(clean, 50)


@needs_open_data("PAAM hydrogel")
def test_real_paam_approaches_that_start_off_their_level_read_as_close_to_white_noise(tmp_path):
    # Public JPK curves of one PAAm spot at 5 and 15 µm/s (Abuhattum et al. 2022): their approaches start 26 and
    # 16 pN off the baseline's line; left in, κ² read 4.15 and 4.86. real-noise.md measured PAAm's noise on the
    # same public curves as close to white (block-mean std 0.9–1.4× the white expectation: κ² 0.8–2.0).
    from ptwin.data.import_afm import main as import_afm

    files = ["speed 5/PAA_speed 5_4nN_3.tab", "speed 15/PAA_speed 15_4nN.tab"]
    options = ["--probe-radius", "5e-6", "--viscosity", "1e-3", "--thickness", "8e-5"]
    import_afm([*(str(OPEN_DATA / "PAAM hydrogel" / name) for name in files), "--out", str(tmp_path), *options])
    for curve in curve_kinematics(load_recordings(tmp_path)):
        assert curve.noise.unsettled > 0 and curve.noise.inflation < 2.05  # 2.0 and 1.37; 4.15 and 4.86 left in


def test_what_the_noise_model_leaves_out_of_a_baseline_is_said(tmp_path, coarse_cache):
    # Nothing is dropped unsaid: the first blocks of v4's baseline sit 5σ off its line, and the notes say so.
    import pandas as pd

    from ptwin.pipeline.prepare import prepare

    folder = simulated_set(tmp_path / "set", z_start=-2e-6, samples=1200)
    table = pd.read_csv(folder / "curves.csv")
    first = table.index[table["curve"] == "v4"][:50]
    table.loc[first, "force"] += 1.5e-9
    table.to_csv(folder / "curves.csv", index=False)
    prepared = prepare(settings_for(f"data.path={folder}", "pgd=coarse", f"cache_dir={coarse_cache}"), lambda _: None)
    said = [note for note in prepared.notes if "left out of its noise model" in note]
    assert len(said) == 1 and said[0].startswith("v4: the first 50 samples of its pre-contact baseline")


@pytest.mark.parametrize(("lag1", "size"), [(0.0, 300), (0.9, 500), (0.99, 1000)])
def test_stationary_noise_is_rarely_taken_for_a_start_off_its_level(lag1, size):
    # The block means' own scatter sets the ceiling: 0.9–1.8% of 6-block records, at most 0.8% of 10-block ones and
    # 0.2% of 20-block ones lost their start in 1000 draws of white + AR(1) noise; here at most 9 of 300.
    rng = np.random.default_rng(7)
    z = np.linspace(-3e-6, -1e-6, size)
    trimmed = sum(level_settled(z, correlated_noise(rng, size, 1.0, lag1), 50) > 0 for _ in range(300))
    assert trimmed <= 9


@pytest.mark.parametrize(("lag1", "size"), [(0.0, 400), (0.9, 800), (0.98, 2600)])
def test_stationary_noise_is_rarely_taken_for_ringing(lag1, size):
    # Exchangeable blocks: the first rarely reaches twice the largest of the second half's (0 %, 0.6 % and 0.35 %
    # of 2000 draws of these; of 300-sample records at lag-1 0.9, 4 %); 300 draws here, at most 3 left anything out.
    rng = np.random.default_rng(5)
    trimmed = sum(settled(correlated_noise(rng, size, 1.0, lag1), 50) > 0 for _ in range(300))
    assert trimmed <= 3


def test_a_set_whose_baselines_hold_no_noise_is_refused_unless_its_noise_is_given(tmp_path, coarse_cache):
    # A simulation without noise, or a force smoothed or exported to few digits: the baselines are flat to
    # rounding, no correlation can be fitted (0/0) and every χ² would be over a σ of rounding: such a set read
    # "284× the noise std" and unexplained, through a division by zero, before it was refused.
    folder = simulated_set(tmp_path / "set", noise_std=0.0, z_start=-1.0e-6)  # baselines long enough to measure
    settings = settings_for(f"data.path={folder}", "pgd=coarse", f"cache_dir={coarse_cache}")
    flat = r"curve\(s\) v0.5, v4, v20, v80: the baseline before contact is flat to rounding"
    with pytest.raises(RecordingError, match=flat):
        prepare(settings, progress=lambda _: None)
    meta = folder / "meta.yaml"
    meta.write_text(meta.read_text() + "noise_std: 1.0e-11\n")
    assert prepare(settings, progress=lambda _: None).noise_floor == pytest.approx(1e-11, rel=1e-9, abs=0)


def test_a_curve_whose_noise_reads_zero_off_its_second_differences_is_refused(tmp_path, coarse_cache):
    # A detector stuck once the probe pressed, on a curve whose baseline is too short to read its noise on: its
    # second differences are mostly zero, the robust σ read off them 0, and the base model's fit divided by it
    # ("the model or its derivatives are not finite … check the probe radius, spring constant and sample
    # thickness", naming no curve) before it was refused.
    folder = simulated_set(tmp_path / "set")
    table = pd.read_csv(folder / "curves.csv")
    stuck = (table["curve"] == "v4") & (table["z"] > 0)
    table.loc[stuck, "force"] = table.loc[stuck, "force"].iloc[0]
    table.to_csv(folder / "curves.csv", index=False)
    settings = settings_for(f"data.path={folder}", "pgd=coarse", f"cache_dir={coarse_cache}")
    with pytest.raises(RecordingError, match=r"curve\(s\) v4: half its second differences or more are zero"):
        prepare(settings, progress=lambda _: None)
    meta = folder / "meta.yaml"
    meta.write_text(meta.read_text() + "noise_std: 1.0e-10\n")
    assert prepare(settings, progress=lambda _: None).noise_floor == pytest.approx(1e-10, rel=1e-9, abs=0)


def test_the_inflation_of_a_long_mean_is_the_limit_of_the_block_inflation():
    # White + AR(1), c 0.4, φ 0.9: (1 − c) + c(1 + φ)/(1 − φ) = 8.2, what means of ever longer blocks tend to.
    assert mean_inflation(0.4, 0.9) == pytest.approx(0.6 + 0.4 * 1.9 / 0.1)
    assert model_inflation(0.4, 0.9, 200_000) == pytest.approx(mean_inflation(0.4, 0.9), rel=1e-3)
    assert mean_inflation(-0.3, 0.5) == 1.0  # anti-correlated noise is never read as more informative than white


def baselines_of_a_set(rng, speeds, spread=0.0, lag1=0.0, size=300):
    """The noise models of baselines of ``size`` samples at ``speeds`` (one sampling rate: the z spacing grows with
    the speed), each with the instrument's tilt and a drag gradient ∝ speed, white or AR(1) noise of 10 pN, and a
    slope of its own of ``spread`` standard errors of a slope over white noise (a drift straight over a baseline)."""
    step, tilt, drag = 1e-3, 3e-3, 2e2  # [s], [N/m], [N s/m²]
    own = spread * np.sqrt(slope_variance(size, 0.0, 0.0))
    models = []
    for speed in speeds:
        z = -1e-6 + speed * step * np.arange(size)
        noise = correlated_noise(rng, size, 1e-11, lag1) + 1e-11 * own * rng.standard_normal() * np.arange(size)
        models.append(baseline_noise(step * np.arange(size), z, (tilt + drag * speed) * z + noise, 50))
    return models


@pytest.mark.parametrize("lag1", [0.0, 0.5])
@pytest.mark.parametrize("speeds", [(2e-6,) * 4, (1e-6, 4e-6, 16e-6, 64e-6)])
def test_baseline_slopes_within_the_noise_read_as_a_drift_at_the_false_alarm_rate(lag1, speeds):
    # 300 sets of four baselines whose slopes are the tilt, the drag gradient and noise: the drift's χ² exceeds its
    # 1% quantile 0 to 4 times (measured); with no line in the speed fitted, 300 of 300 sets at four speeds did.
    rng = np.random.default_rng(11)
    drifts = [
        pooled(baselines_of_a_set(rng, speeds, lag1=lag1), [1] * 4, [1e-3] * 4, 50, 0.01).drift for _ in range(300)
    ]
    read = [d for d in drifts if d is not None]  # None: baselines unsettled at their start left too few
    assert len(read) >= 290 and sum(d.share > 0 for d in read) <= 7
    assert np.mean([d.chi_square / d.dof for d in read]) == pytest.approx(1.0, abs=0.2)


def test_baseline_slopes_that_scatter_beyond_the_noise_read_as_a_drift_of_their_size():
    # Eighty curves at one speed, each baseline with a slope of its own of 3 standard errors: a drift whose slope
    # variance over a baseline is 9 times white noise's on top of it.
    rng = np.random.default_rng(12)
    models = baselines_of_a_set(rng, (2e-6,) * 80, spread=3.0)
    drift = pooled(models, [1] * 80, [1e-3] * 80, 50, 0.01).drift
    assert drift.dof >= 72 and drift.memory == pytest.approx(np.exp(-1 / 300), rel=0.01)  # a start unsettled: a few out
    excess = drift.share * slope_variance(300, 1.0, drift.memory) / slope_variance(300, 0.0, 0.0)
    assert excess == pytest.approx(9.0, rel=0.35)  # χ² on ~79 degrees of freedom: ±16%
    # Four such curves: beyond the noise at most seeds (32 of 40 measured); two at two speeds leave the line in the
    # speed no degree of freedom, so nothing is read
    found = [
        pooled(m, [1] * 4, [1e-3] * 4, 50, 0.01).drift.share > 0
        for m in (baselines_of_a_set(rng, (2e-6,) * 4, 3.0) for _ in range(40))
    ]
    assert sum(found) >= 20
    assert pooled(baselines_of_a_set(rng, (5e-6, 15e-6), 3.0), [1, 1], [1e-3] * 2).drift is None


def test_a_noise_std_given_elsewhere_leaves_the_slopes_read_against_their_own_scatter():
    # A lab's σ 1.5 times the baselines' own (three of four cell records read 0.76 of the bench-sets' σ): the
    # slopes' errors follow the scatter they were read on, so χ² is what it is without it (read against the σ
    # given, 2.25 times low), and the drift's variance, in units of the σ given, 2.25 times smaller.
    rng = np.random.default_rng(12)
    models = baselines_of_a_set(rng, (2e-6,) * 80, spread=3.0)
    own = pooled(models, [1] * 80, [1e-3] * 80, 50, 0.01).drift
    given = [with_std(m, 1.5 * m.std, "noise_std of meta.yaml") for m in models]
    drift = pooled(given, [1] * 80, [1e-3] * 80, 50, 0.01).drift
    assert drift.chi_square == pytest.approx(own.chi_square) and drift.share == pytest.approx(own.share / 2.25)


def test_the_slope_variance_is_the_quadratic_form_of_the_noise_models_correlation():
    x = np.arange(200) - 99.5
    lags = np.abs(np.subtract.outer(np.arange(200), np.arange(200)))
    correlation = np.where(lags == 0, 1.0, 0.4 * 0.9**lags)
    assert slope_variance(200, 0.4, 0.9) == pytest.approx(x @ correlation @ x / (x @ x) ** 2, rel=1e-12)
    assert slope_variance(200, 0.0, 0.0) == pytest.approx(12 / (200**3 - 200), rel=1e-12)
