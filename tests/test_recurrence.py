"""Hereditary terms: the recurrence against a loop, its two solvers against each other, the lags against closed
forms."""

import math

import pytest
import torch

from ptwin.physics.recurrence import (
    _parallel_scan,
    _substituted,
    first_order_lag,
    linear_recurrence,
    relaxation_integral,
)


def test_scan_equals_the_sequential_recurrence_and_restarts():
    generator = torch.Generator().manual_seed(0)
    a = torch.rand(1000, generator=generator, dtype=torch.float64)
    b = torch.randn(1000, generator=generator, dtype=torch.float64)
    a[[0, 400]] = 0.0  # two curves
    expected, x = torch.empty_like(b), 0.0
    for i in range(1000):
        x = a[i] * x + b[i]
        expected[i] = x
    torch.testing.assert_close(linear_recurrence(a, b), expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("reverse", [False, True])
def test_substitution_and_parallel_scan_agree_on_many_recurrences_laid_end_to_end(reverse):
    """The CPU's solver lays the recurrences of the leading dimensions end to end in one LAPACK call; a coupling
    left between one's end and the next one's start would carry x across (the GPU's scan never does)."""
    generator = torch.Generator().manual_seed(2)
    a = torch.rand(4, 3, 257, generator=generator, dtype=torch.float64) * 1.1  # a growing mode too
    b = torch.randn(4, 3, 257, generator=generator, dtype=torch.float64) + 5.0
    a[..., 100] = 0.0
    torch.testing.assert_close(_substituted(a, b, reverse), _parallel_scan(a, b, reverse), rtol=1e-12, atol=1e-10)
    # each recurrence alone gives what it gives beside the others
    torch.testing.assert_close(_substituted(a[2, 1], b[2, 1], reverse), _substituted(a, b, reverse)[2, 1])


@pytest.mark.parametrize("samples", [50, 500])
def test_lag_of_a_ramp_is_exact_on_any_grid(samples):
    # τ y' + y = t from y(0) = 0: y = t − τ(1 − e^{−t/τ}), exact for inputs linear between samples.
    tau = 0.3
    time = torch.linspace(0, 2, samples, dtype=torch.float64) ** 1.5
    start = torch.arange(samples) == 0
    lagged = first_order_lag(time, torch.full_like(time, tau), time, start)
    torch.testing.assert_close(lagged, time - tau * (1 - torch.exp(-time / tau)), rtol=0, atol=1e-13)


def test_relaxation_integral_of_a_ramp_and_zero_time_constant():
    # q = ∫ e^{−(t−s)/τ} ds for s' = 1: q = τ(1 − e^{−t/τ}); τ = 0 leaves no memory.
    time = torch.linspace(0, 3, 301, dtype=torch.float64)
    start = torch.arange(301) == 0
    q = relaxation_integral(time, torch.full_like(time, 0.5), time, start)
    torch.testing.assert_close(q, 0.5 * (1 - torch.exp(-time / 0.5)), rtol=0, atol=1e-13)
    assert torch.equal(first_order_lag(time.sin(), torch.zeros_like(time), time, start), time.sin())


def test_lag_gradient_in_the_time_constant():
    time = torch.linspace(0, 1, 40, dtype=torch.float64)
    start = torch.arange(40) == 0
    forcing = time**2

    def lag(log_tau):
        return first_order_lag(forcing, log_tau.exp().expand(40), time, start)

    assert torch.autograd.gradcheck(lag, (torch.tensor(math.log(0.2), dtype=torch.float64, requires_grad=True),))


def test_scan_derivatives_first_second_and_forward():
    """The scan is one autograd node with derivatives of its own (scans the other way): checked against
    finite differences in both inputs, to second order (LM's Jacobians differentiate a gradient) and in
    forward mode, on two curves of a few modes."""
    generator = torch.Generator().manual_seed(1)
    a = torch.rand(3, 37, generator=generator, dtype=torch.float64)
    a[:, 20] = 0.0
    b = torch.randn(3, 37, generator=generator, dtype=torch.float64)
    inputs = (a.requires_grad_(True), b.requires_grad_(True))
    assert torch.autograd.gradcheck(linear_recurrence, inputs, check_forward_ad=True)
    assert torch.autograd.gradgradcheck(linear_recurrence, inputs)
    jacobian = torch.func.jacfwd(lambda b: linear_recurrence(a.detach(), b))(b.detach())
    torch.testing.assert_close(
        jacobian, torch.autograd.functional.jacobian(lambda b: linear_recurrence(a.detach(), b), b.detach())
    )


def test_the_node_skips_the_signature_binding_outside_torch_func(monkeypatch):
    """``Function.apply`` binds its arguments by ``inspect.signature`` on every call, a tenth of a fit's Jacobian;
    the recurrence's node goes to the C++ node at once, with the same value and derivatives."""
    import inspect

    from ptwin.physics.recurrence import _LinearRecurrence

    generator = torch.Generator().manual_seed(4)
    a, b = (torch.rand(2, 30, generator=generator, dtype=torch.float64, requires_grad=True) for _ in range(2))
    bound = torch.autograd.Function.apply.__func__(_LinearRecurrence, a, b, False)
    expected = torch.autograd.grad(bound.square().sum(), (a, b))

    def refuse(*_, **__):
        raise AssertionError("a signature was bound")

    monkeypatch.setattr(inspect, "signature", refuse)
    x = linear_recurrence(a, b)
    assert torch.equal(x, bound)
    for found, wanted in zip(torch.autograd.grad(x.square().sum(), (a, b)), expected):
        assert torch.equal(found, wanted)
