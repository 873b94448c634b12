"""Kinematics against closed forms: contact radius, smoothed derivative, noise floor."""

import numpy as np
import pytest

from ptwin.data.kinematics import contact_radius, smoothed_derivative
from ptwin.data.noise import second_difference_std


def test_contact_radius_is_the_spherical_cap():
    rho = 12e-6
    assert contact_radius(np.array([-1e-7, 0.0, rho]), rho) == pytest.approx([0.0, 0.0, rho])
    w = 2e-6
    assert contact_radius(np.array([w]), rho)[0] == pytest.approx(np.sqrt(2 * rho * w - w * w))


def test_smoothed_derivative_is_exact_on_lines_and_on_uniformly_sampled_quadratics():
    rng = np.random.default_rng(0)
    uneven = np.sort(rng.uniform(0, 1, 2000))
    assert smoothed_derivative(uneven, 3e-6 * uneven + 1e-7, 101) == pytest.approx(np.full(2000, 3e-6), rel=1e-8)
    time = np.linspace(0, 1, 2000)
    interior = slice(60, -60)
    derivative = smoothed_derivative(time, 3e-6 * time + 2e-6 * time**2, 101)
    assert derivative[interior] == pytest.approx((3e-6 + 4e-6 * time)[interior], rel=1e-8)


def test_smoothed_derivative_beats_finite_differences_on_noise():
    rng = np.random.default_rng(0)
    time = np.linspace(0, 1, 2000)
    signal = 3e-6 * time + 2e-6 * time**2
    exact = 3e-6 + 4e-6 * time
    interior = slice(60, -60)
    noisy = signal + rng.normal(0, 1e-10, time.size)
    smooth_error = np.std(smoothed_derivative(time, noisy, 101)[interior] - exact[interior])
    raw_error = np.std(np.gradient(noisy, time)[interior] - exact[interior])
    assert smooth_error < raw_error / 30


def test_noise_floor_recovers_white_noise_under_a_smooth_signal():
    rng = np.random.default_rng(1)
    t = np.linspace(0, 1, 4000)
    force = 5e-7 * t**1.5 + rng.normal(0, 3e-10, t.size)
    assert second_difference_std(force) == pytest.approx(3e-10, rel=0.08)
