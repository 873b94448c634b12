"""Levenberg–Marquardt: a nonlinear truth recovered, the covariance of a linear fit exact."""

import math
import subprocess
import sys

import pytest
import torch

from ptwin.fitting.lm import LevenbergMarquardt, Traced, covariance
from ptwin.fitting.physics_fit import DAMPING_DECREASE, LOG_STEP


def test_the_reverse_mode_jacobian_is_the_closed_form_even_where_a_parameter_is_unused_or_enters_linearly():
    t = torch.linspace(0, 4, 50, dtype=torch.float64)
    theta = torch.tensor([2.0, -1.3, 0.7, 5.0], dtype=torch.float64)  # amplitude, log rate, offset, unused

    def curve(p):
        return p[0] * torch.exp(-p[1].exp() * t) + p[2]

    decay = torch.exp(-theta[1].exp() * t)
    expected = torch.stack(
        [decay, -theta[0] * theta[1].exp() * t * decay, torch.ones_like(t), torch.zeros_like(t)], dim=-1
    )
    jacobian, value = Traced(curve, theta).jacobian_and_value()
    torch.testing.assert_close(jacobian, expected, rtol=1e-14, atol=1e-14)
    torch.testing.assert_close(value, curve(theta))
    other = torch.ones_like(t, requires_grad=True)  # a parameter of the module that is not in θ
    for unrelated in (lambda p: t.clone(), lambda p: 2 * other):  # no path from θ at all
        constant, _ = Traced(unrelated, theta).jacobian_and_value()
        assert constant.shape == (50, 4) and not constant.any()


def test_a_jacobian_leaves_torchs_symbolic_shapes_and_sympy_unimported():
    # Their import is 0.4 s of every run: gradients of scalars, never a grad_output whose shape torch checks.
    program = (
        "import sys, torch\n"
        "from ptwin.fitting.lm import Traced\n"
        "theta = torch.tensor([0.5, 2.0], dtype=torch.float64)\n"
        "Traced(lambda p: p[0] * torch.linspace(0, 1, 9, dtype=torch.float64) ** p[1], theta).jacobian_and_value()\n"
        "print(sorted(m for m in ('sympy', 'torch.fx.experimental.symbolic_shapes') if m in sys.modules))\n"
    )
    result = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, check=True)
    assert result.stdout.strip() == "[]"


def test_recovers_an_exponential_decay_from_a_poor_start():
    t = torch.linspace(0, 4, 200, dtype=torch.float64)
    truth = torch.tensor([2.0, -1.3], dtype=torch.float64)  # amplitude, log rate

    def residual(theta):
        return theta[0] * torch.exp(-theta[1].exp() * t) - truth[0] * torch.exp(-truth[1].exp() * t)

    solver = LevenbergMarquardt(residual, torch.tensor([0.5, 0.5], dtype=torch.float64))
    theta = solver.run(200, tolerance=0.0)
    torch.testing.assert_close(theta, truth, rtol=1e-8, atol=1e-8)


@pytest.mark.parametrize(("decrease", "accepted", "most"), [(1 / 3, 25, 34), (0.1, 14, 23)])
def test_a_parameter_whose_force_grows_e_fold_a_unit_is_crossed_in_fewer_steps_where_damping_falls_faster(
    decrease, accepted, most
):
    # log K from the fluid-off start: F_D ∝ 1/K. Accepted steps have gain ≈ 1, and each moves θ by ln(1/cap) as
    # the damping falls by the cap: 25 accepted at Nielsen's 1/3, 14 at Marquardt's 1/10, after the same 8
    # rejected from the start. At θ = 0 the run ends on the first rejected step, which promised less than the
    # tolerance: ten more, each damped harder, left θ where it was.
    t = torch.linspace(0.5, 2.0, 50, dtype=torch.float64)

    def residual(theta):
        return (torch.exp(-theta[0]) - 1.0) * t

    solver = LevenbergMarquardt(residual, torch.tensor([16.0], dtype=torch.float64), decrease=decrease)
    steps = []
    solver.run(200, tolerance=1e-12, callback=steps.append)
    assert abs(solver.theta.item()) < 1e-8
    assert sum(step.accepted for step in steps) == accepted
    assert len(steps) == most and not steps[-1].accepted


def test_a_step_limit_crosses_the_e_folds_in_accepted_steps_of_that_length_from_the_start():
    # The same 16 e-folds with log K's limit of the physics fits (two decades a step, DAMPING_DECREASE): the
    # linearisation of e^(−θ) promises a step to θ = 0 at once, which falls short eight times above while the
    # damping grows; held to 4.6 the first three steps are accepted, each the limit long, and θ ends where it did.
    t = torch.linspace(0.5, 2.0, 50, dtype=torch.float64)

    def residual(theta):
        return (torch.exp(-theta[0]) - 1.0) * t

    limit = torch.tensor([LOG_STEP], dtype=torch.float64)
    solver = LevenbergMarquardt(residual, torch.tensor([16.0]).double(), decrease=DAMPING_DECREASE, step_limit=limit)
    path, steps = [solver.theta.item()], []
    solver.run(200, tolerance=1e-12, callback=lambda step: (steps.append(step), path.append(solver.theta.item())))
    assert abs(solver.theta.item()) < 1e-8
    assert [step.accepted for step in steps[:3]] == [True, True, True]
    assert path[3] == pytest.approx(16.0 - 3 * LOG_STEP, rel=1e-12)
    assert max(abs(a - b) for a, b in zip(path, path[1:])) <= LOG_STEP * (1 + 1e-12)
    assert len(steps) < 23  # the unlimited run's steps (above)


def test_a_long_step_read_in_the_reciprocal_keeps_its_promise_where_the_residual_is_linear_there():
    # The same 16 e-folds, log K's long steps read in u = e^(−θ), where the residual is linear (log K's Darcy force in
    # 1/K): three steps at the limit, then one asked for δ −8, read as u × 9, to within 1e-6 of θ = 0, each
    # promising the decrease it gives; the steps within the limit are θ's own. 7 steps, none rejected before the
    # one that ends the run; read in θ, 19 (7 rejected: the step asked for δ −8 went to the limit again).
    t = torch.linspace(0.5, 2.0, 50, dtype=torch.float64)

    def residual(theta):
        return (torch.exp(-theta[0]) - 1.0) * t

    limit, start = torch.tensor([LOG_STEP], dtype=torch.float64), torch.tensor([16.0], dtype=torch.float64)
    solver = LevenbergMarquardt(
        residual, start, decrease=DAMPING_DECREASE, step_limit=limit, reciprocal=torch.tensor([True])
    )
    costs, steps = [0.5 * residual(start).square().sum().item()], []
    solver.run(200, tolerance=1e-12, callback=lambda step: (steps.append(step), costs.append(step.cost)))
    assert abs(solver.theta.item()) < 1e-8
    assert [step.accepted for step in steps] == [True] * 6 + [False]
    for step, before, after in zip(steps[:4], costs, costs[1:]):
        assert before - after == pytest.approx(step.predicted, rel=1e-9)


def test_an_entry_read_in_its_reciprocal_needs_a_step_limit_and_the_physics_fits_read_only_log_k_so():
    from torch import nn

    from ptwin.fitting.lm import ParameterVector
    from ptwin.fitting.physics_fit import physics_solver
    from ptwin.physics.model import PERMEABILITY

    with pytest.raises(ValueError, match="finite step_limit"):
        LevenbergMarquardt(lambda theta: theta, torch.zeros(1, dtype=torch.float64), reciprocal=torch.tensor([True]))
    module = nn.Module()
    module.fluid = nn.Module()
    module.fluid.log_permeability = nn.Parameter(torch.tensor([-36.0], dtype=torch.float64))
    module.log_tau = nn.Parameter(torch.tensor([0.0], dtype=torch.float64))
    vector = ParameterVector(module, [PERMEABILITY, "log_tau"])
    solver = physics_solver(lambda theta: theta, vector.get(), vector)
    assert solver.reciprocal.tolist() == [True, False]
    assert physics_solver(lambda theta: theta, vector.get()[1:], vector, torch.tensor([1])).reciprocal.tolist() == [
        False
    ]


def test_the_physics_fits_move_every_parameter_fitted_in_log_at_most_two_decades_a_step():
    # A pore relaxation doing nothing (M 4e6 Pa), refitted with K fixed a little higher: its gradient nearly nil, one
    # step went from log M 19.9 to 449.8, where its derivatives overflow, and the profile read that as the model
    # breaking down (an open side of K's interval). A quantity ∝ 1/M there: the step is held to two decades.
    from torch import nn

    from ptwin.fitting.lm import ParameterVector
    from ptwin.fitting.physics_fit import physics_solver

    module = nn.Module()
    module.log_M = nn.Parameter(torch.tensor([19.9], dtype=torch.float64))
    module.gamma = nn.Parameter(torch.tensor([0.0], dtype=torch.float64))
    vector = ParameterVector(module, ["log_M", "gamma"])
    t = torch.linspace(0.5, 2.0, 50, dtype=torch.float64)

    def residual(theta):
        return torch.cat([(1e-12 * torch.exp(-theta[0]) - 1e-9) * t, theta[1] - 1.0 + 0 * t])

    solver = physics_solver(residual, vector.get(), vector)
    assert solver.step_limit.tolist() == [LOG_STEP, math.inf]
    before = solver.theta.clone()
    solver.step()
    assert abs(solver.theta[0] - before[0]) <= LOG_STEP * (1 + 1e-12)


def test_a_run_says_whether_it_settled_or_ended_at_its_step_cap():
    # The same 16 e-folds at two decades a step: three steps leave it falling, two hundred let it settle.
    t = torch.linspace(0.5, 2.0, 50, dtype=torch.float64)
    limit = torch.tensor([LOG_STEP], dtype=torch.float64)
    for steps, settled in ((3, False), (200, True)):
        solver = LevenbergMarquardt(
            lambda theta: (torch.exp(-theta[0]) - 1.0) * t, torch.tensor([16.0]).double(), step_limit=limit
        )
        solver.run(steps, tolerance=1e-12)
        assert solver.settled is settled and int(solver.state["iteration"]) <= steps


def _counted_decay_fit() -> tuple[LevenbergMarquardt, list]:
    """LM on a decay a·exp(−e^b·t) from a poor start (truth a = 2, b = −1.3), and the θ of each evaluation."""
    t = torch.linspace(0, 4, 200, dtype=torch.float64)
    calls = []

    def residual(theta):
        calls.append(theta.detach().clone())
        return theta[0] * torch.exp(-theta[1].exp() * t) - 2.0 * torch.exp(-math.exp(-1.3) * t)

    return LevenbergMarquardt(residual, torch.tensor([0.5, 0.5], dtype=torch.float64)), calls


def test_each_step_evaluates_the_model_once_its_jacobian_taken_from_the_accepted_trial():
    solver, calls = _counted_decay_fit()
    steps = []
    solver.run(200, tolerance=0.0, callback=steps.append)
    assert any(not step.accepted for step in steps) and sum(step.accepted for step in steps) > 5
    assert len(calls) == 1 + len(steps)  # the first linearisation, then one trial a step
    torch.testing.assert_close(solver.theta, torch.tensor([2.0, -1.3], dtype=torch.float64), rtol=1e-8, atol=1e-8)


@pytest.mark.parametrize("iterations", [10, 200])  # the run ends on an accepted step; on a rejected one
def test_the_jacobian_where_a_run_ends_is_the_runs_own_the_model_not_evaluated_again(iterations):
    solver, calls = _counted_decay_fit()
    steps = []
    solver.run(iterations, tolerance=1e-10, callback=steps.append)
    assert steps[-1].accepted == (iterations == 10)
    evaluated = len(calls)
    jacobian, r = solver.linearised()
    assert len(calls) == evaluated
    fresh_jacobian, fresh_r = solver.linearise(solver.theta)
    assert torch.equal(jacobian, fresh_jacobian) and torch.equal(r, fresh_r)


def test_a_settled_fit_stops_once_a_step_gains_less_than_asked_and_no_sooner():
    # Noisy data: the cost converges to its floor; "settled" ends the run at the first accepted step
    # gaining less than it (absolute), where the relative tolerance alone runs on to machine precision.
    t = torch.linspace(0, 4, 200, dtype=torch.float64)
    noise = 0.05 * torch.randn(200, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    data = 2.0 * torch.exp(-0.3 * t) + noise

    def residual(theta):
        return (theta[0] * torch.exp(-theta[1].exp() * t) - data) / 0.05

    start = torch.tensor([0.5, 0.5], dtype=torch.float64)
    steps = []
    settled = LevenbergMarquardt(residual, start)
    settled.run(200, tolerance=0.0, callback=steps.append, settled=1e-3)
    full = LevenbergMarquardt(residual, start)
    full.run(200, tolerance=0.0)
    accepted = [step.cost for step in steps if step.accepted]
    gains = [before - after for before, after in zip(accepted, accepted[1:])]
    assert gains[-1] < 1e-3 and all(gain >= 1e-3 for gain in gains[:-1])
    assert settled.state["iteration"] < full.state["iteration"]
    assert 0 <= settled.state["cost"] - full.state["cost"] < 1e-2


def test_learning_rate_scales_each_step():
    def residual(theta):
        return theta - torch.tensor([1.0, 1.0], dtype=torch.float64)

    solver = LevenbergMarquardt(residual, torch.zeros(2, dtype=torch.float64), torch.tensor([1.0, 0.5]), damping=0.0)
    solver.step()
    torch.testing.assert_close(solver.theta, torch.tensor([1.0, 0.5], dtype=torch.float64))


def test_covariance_of_a_straight_line_fit_matches_the_textbook():
    generator = torch.Generator().manual_seed(1)
    x = torch.linspace(0, 1, 50, dtype=torch.float64)
    y = 3 * x + 1 + 0.1 * torch.randn(50, generator=generator, dtype=torch.float64)
    design = torch.stack([x, torch.ones_like(x)], 1)
    solver = LevenbergMarquardt(lambda theta: design @ theta - y, torch.zeros(2, dtype=torch.float64))
    theta = solver.run(20)
    jacobian, r = solver.linearise(theta)
    s2 = (r @ r) / 48
    torch.testing.assert_close(covariance(jacobian, r), s2 * torch.linalg.inv(design.T @ design))


def test_parameters_the_data_cannot_fix_are_not_identified_never_certain():
    # y = (a + b)·x: only a + b is fixed by the data; c is fixed on its own.
    x = torch.linspace(0, 1, 40, dtype=torch.float64)
    design = torch.stack([x, x, x**2], 1)
    r = 0.01 * torch.sin(7 * x)
    cov = covariance(design, r)
    assert torch.isinf(cov[0, 0]) and torch.isinf(cov[1, 1])
    assert torch.isnan(cov[0, 2]) and torch.isnan(cov[2, 1])
    identified = torch.stack([x, x**2], 1)  # the model in (a + b, c): the textbook variance of c
    expected = (r @ r) / 37 * torch.linalg.inv(identified.T @ identified)[1, 1]
    torch.testing.assert_close(cov[2, 2], expected)


def test_a_parameter_that_barely_acts_gets_an_infinite_variance_and_leaves_the_others_exact():
    # A column of norm ~1e-156 (a pore term's K in its K → 0 limit on a real creep) squares to a denormal in JᵀJ:
    # scaled by its reciprocal, the eigensolver was fed infinities and failed. Rescaling a parameter leaves the
    # others' covariance as it is: the textbook's of the same model with that parameter at unit scale.
    x = torch.linspace(0, 1, 50, dtype=torch.float64)
    design = torch.stack([x, torch.ones_like(x), x**2], 1)
    r = 0.01 * torch.sin(7 * x)
    cov = covariance(design * torch.tensor([1.0, 1.0, 1e-160], dtype=torch.float64), r)
    assert torch.isinf(cov[2, 2])
    torch.testing.assert_close(cov[:2, :2], (r @ r) / 47 * torch.linalg.inv(design.T @ design)[:2, :2])


def test_a_step_the_model_cannot_evaluate_is_rejected_not_fatal():
    # The model is defined for θ < 1 only (like a depth beyond the sample); the optimum is at 0.9.
    def residual(theta):
        if (theta >= 1).any():
            raise ValueError("theta off its domain")
        return torch.log1p(-theta) - torch.log1p(torch.tensor([-0.9], dtype=torch.float64))

    solver = LevenbergMarquardt(residual, torch.tensor([0.0], dtype=torch.float64), damping=1e-9)
    theta = solver.run(100, tolerance=0.0)
    torch.testing.assert_close(theta, torch.tensor([0.9], dtype=torch.float64))


def test_a_start_the_model_cannot_evaluate_is_a_fit_error_in_words():
    import pytest

    from ptwin.fitting.lm import FitError

    def residual(theta):
        return torch.sqrt(theta)  # NaN derivative at 0, NaN value below

    solver = LevenbergMarquardt(residual, torch.tensor([-1.0], dtype=torch.float64))
    with pytest.raises(FitError, match="not finite"):
        solver.step()


def test_a_model_that_fails_without_a_message_is_a_fit_error_naming_its_error():
    import pytest

    from ptwin.fitting.lm import FitError

    def residual(theta):
        raise RuntimeError()  # the error's first line was taken by index: IndexError, no FitError

    solver = LevenbergMarquardt(residual, torch.tensor([1.0], dtype=torch.float64))
    with pytest.raises(FitError, match=r"^the model cannot be evaluated \(RuntimeError\)$"):
        solver.step()


def test_a_system_too_singular_to_solve_is_retried_with_more_damping(monkeypatch):
    # The first normal equations "fail" to solve: no step. The run goes on with a larger damping rather than
    # reading the empty step as one that promised nothing.
    t = torch.linspace(0, 4, 200, dtype=torch.float64)

    def residual(theta):
        return theta[0] * torch.exp(-theta[1] * t) - 2.0 * torch.exp(-0.3 * t)

    solve, failures = torch.linalg.solve, []

    def failing_once(*args, **kwargs):
        if not failures:
            failures.append(True)
            raise RuntimeError("linalg.solve: The solver failed because the input matrix is singular.")
        return solve(*args, **kwargs)

    monkeypatch.setattr(torch.linalg, "solve", failing_once)
    solver = LevenbergMarquardt(residual, torch.tensor([1.0, 1.0], dtype=torch.float64))
    steps = []
    solver.run(100, tolerance=1e-12, callback=steps.append)
    assert failures and not steps[0].accepted and steps[0].predicted is None
    torch.testing.assert_close(solver.theta, torch.tensor([2.0, 0.3], dtype=torch.float64), rtol=1e-8, atol=1e-8)
