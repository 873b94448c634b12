"""Power-law rheology: Ting's integral through a sum of exponentials, against closed forms,
direct quadrature of the integral, and gradcheck."""

import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from ptwin.physics.hereditary import hereditary_inverse
from ptwin.physics.power_law import T0, kernel_for, kernel_modes, ting_integral
from ptwin.physics.recurrence import relaxation_integral
from ptwin.physics.terms import PowerLawRheology

ALPHAS = [0.0, 0.01, 0.1, 0.3, 0.49]


@pytest.mark.parametrize("alpha", ALPHAS)
def test_the_kernel_is_a_power_law_to_1e_4_over_the_time_scales_of_the_data(alpha):
    c0, weights, times = kernel_modes(torch.tensor(alpha, dtype=torch.float64), 1e-4, 1e3)
    tau = torch.logspace(-4, 3, 2000, dtype=torch.float64)
    kernel = c0 + (weights[None, :] * torch.exp(-tau[:, None] / times[None, :])).sum(1)
    assert (kernel / (tau / T0) ** -alpha - 1).abs().max() < 1e-4
    assert weights.numel() < 60


def hertz(depth, modulus=5e3, radius=5e-6):
    return 4.0 / 3.0 * modulus * math.sqrt(radius) * depth.clamp(min=0) ** 1.5


@pytest.mark.parametrize("alpha", [0.05, 0.2, 0.4])
def test_a_constant_speed_ramp_matches_the_closed_form(alpha):
    # Rigid cantilever, w = v·t: F(t) = 4/3·√ρ·E*·t0^α·v^1.5·Γ(1−α)Γ(2.5)/Γ(2.5−α)·t^(1.5−α).
    speed, modulus, radius = 10e-6, 5e3, 5e-6
    time = torch.linspace(0, 0.08, 4001, dtype=torch.float64)
    start = torch.arange(time.numel()) == 0
    elastic = hertz(speed * time, modulus, radius)
    force = ting_integral(elastic, torch.tensor(alpha, dtype=torch.float64), time, start)
    closed = (
        4
        / 3
        * math.sqrt(radius)
        * modulus
        * T0**alpha
        * speed**1.5
        * math.gamma(1 - alpha)
        * math.gamma(2.5)
        / math.gamma(2.5 - alpha)
        * time ** (1.5 - alpha)
    )
    late = time > 0.008
    torch.testing.assert_close(force[late], closed[late], rtol=2e-4, atol=0)


def quadrature(force: np.ndarray, time: np.ndarray, alpha: float) -> np.ndarray:
    """∫₀ᵗ (t − s)^(−α) dF/ds ds for F linear between samples, term by term (O(N²)): each segment's
    slope times ∫ (t − s)^(−α) ds over it, in closed form."""
    slope = np.diff(force) / np.diff(time)
    result = np.zeros_like(force)
    for i in range(1, time.size):
        t, lo, hi = time[i], time[:i], time[1 : i + 1]
        result[i] = np.sum(slope[:i] * ((t - lo) ** (1 - alpha) - (t - hi) ** (1 - alpha)) / (1 - alpha))
    return result


@pytest.mark.parametrize("alpha", [0.05, 0.3, 0.45])
def test_a_recorded_ramp_and_hold_matches_direct_quadrature(alpha):
    # Within 5e-5: the fast tail's mass counts on the latest step (truncated at a margin of 1e4 it left 2.6e-4 out
    # at alpha = 0.45).
    from ptwin.synth.simulator import Experiment, Hold, simulate_curve

    curve = simulate_curve(
        Experiment(probe_radius=5e-6, spring_constant=0.088, effective_modulus=5e3, sample_rate=2000.0),
        10e-6,
        hold=Hold(0.6e-6, 0.5),
        balance=False,
    )
    time = torch.from_numpy(curve.time)
    elastic = hertz(torch.from_numpy(curve.depth))
    start = torch.arange(time.numel()) == 0
    ours = ting_integral(elastic, torch.tensor(alpha, dtype=torch.float64), time, start).numpy()
    reference = quadrature(elastic.numpy(), curve.time, alpha)
    assert np.abs(ours - reference).max() < 5e-5 * np.abs(reference).max()


def test_no_power_law_is_the_elastic_force_itself():
    time = torch.linspace(0, 1, 300, dtype=torch.float64)
    start = (torch.arange(300) == 0) | (torch.arange(300) == 150)
    elastic = torch.sin(3 * time) ** 2
    result = ting_integral(elastic, torch.tensor(0.0, dtype=torch.float64), time, start)
    torch.testing.assert_close(result, elastic, rtol=1e-13, atol=1e-15)


def test_gradcheck_in_alpha_and_in_the_elastic_force():
    time = torch.linspace(0, 0.5, 60, dtype=torch.float64)
    start = torch.arange(60) == 0

    def ting(alpha, elastic):
        return ting_integral(elastic, alpha, time, start)

    alpha = torch.tensor(0.2, dtype=torch.float64, requires_grad=True)
    elastic = (time**1.5).clone().requires_grad_(True)
    assert torch.autograd.gradcheck(ting, (alpha, elastic), check_forward_ad=True)


@pytest.mark.parametrize(("g", "alpha"), [(0.0, 0.45), (3.0, 0.0), (0.5, 0.2)])
def test_the_self_consistent_law_inverts_strong_memory_exactly(g, alpha):
    # A noisy elastic law on an irregular time grid (flat steps included, as on a reference's depth nodes):
    # where a fixed point diverges (g > 1, or alpha ≳ 0.2), forward substitution gives F back.
    generator = torch.Generator().manual_seed(0)
    time = torch.cumsum(torch.rand(200, generator=generator, dtype=torch.float64) * 0.02, 0)
    time[50] = time[49]
    start = torch.arange(200) == 0
    elastic = (time - time[0]) ** 1.5 + 1e-3 * torch.randn(200, generator=generator, dtype=torch.float64)
    alpha = torch.tensor(alpha, dtype=torch.float64)
    tau = torch.tensor([0.3], dtype=torch.float64)
    relaxed = ting_integral(elastic, alpha, time, start) + g * relaxation_integral(
        elastic, tau.expand(200), time, start
    )
    c0, weights, times = kernel_for(alpha, time)
    recovered = hereditary_inverse(
        relaxed, c0 - 1, torch.cat([weights, torch.tensor([g], dtype=torch.float64)]), torch.cat([times, tau]), time
    )
    torch.testing.assert_close(recovered, elastic, rtol=1e-10, atol=1e-12)


def test_the_term_reuses_its_decays_for_the_samples_it_saw_last_and_for_no_others():
    """The kernel's decays depend on the samples' times alone: the term keeps them for the samples a fit
    evaluates again and again, and computes them afresh for any other samples."""
    term = PowerLawRheology(5e-6, alpha=0.2)

    def samples(duration):
        time = torch.cat([torch.linspace(0, duration, 300, dtype=torch.float64)] * 2)
        return SimpleNamespace(time=time, start=torch.arange(600) % 300 == 0)

    first, second = samples(1.0), samples(3.0)
    for recorded in (first, first, second, first):
        elastic = hertz(recorded.time * 1e-6)
        expected = ting_integral(elastic, torch.tensor(0.2, dtype=torch.float64), recorded.time, recorded.start)
        assert torch.equal(term.elastic_force(recorded, elastic), expected - elastic)
