"""The noise model against known truth: AR(1) noise of given std and correlation."""

import numpy as np
import pytest

from ptwin.data.noise import BASELINE, SECOND_DIFFERENCES, ar1_inflation, baseline_noise, curve_noise, pooled
from ptwin.synth.simulator import correlated_noise


def ar1(lag1, size=20000, std=1.3e-11, seed=0):
    return correlated_noise(np.random.default_rng(seed), size, std, lag1)


@pytest.mark.parametrize("lag1", [0.0, 0.3, 0.7])
def test_baseline_noise_recovers_std_correlation_and_block_inflation(lag1):
    time = np.arange(20000) / 2000.0
    z = np.linspace(-2e-6, -0.5e-6, 20000)
    force = ar1(lag1) + 3e-10 + 4e-4 * z  # an offset and a tilt: not noise
    model = baseline_noise(time, z, force, block=50)
    assert model.source == BASELINE
    assert model.std == pytest.approx(1.3e-11, rel=0.03)
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
    assert model.std == pytest.approx(3e-10, rel=0.08)
    assert model.inflation == 1.0


def test_the_set_pools_correlation_from_the_curves_that_measured_it():
    time = np.arange(3000) / 2000.0
    z = np.linspace(-2e-6, -0.5e-6, 3000)
    measured = [baseline_noise(time, z, ar1(0.4, 3000, seed=s), 50) for s in range(3)]
    guessed = curve_noise(time, z, ar1(0.0, 3000), np.zeros(3000, bool), 50)
    set_noise = pooled([*measured, guessed], [1, 1, 1, 1], [5e-4] * 4)
    assert set_noise.source == BASELINE
    assert set_noise.inflation == pytest.approx(np.median([m.inflation for m in measured]))
    assert set_noise.inflation > 1.5  # correlated noise counts for fewer samples
