"""The elastic law under hereditary terms: the block substitution against the operator it inverts, its adjoint
against the dense transpose, its derivatives against finite differences to second order."""

import pytest
import torch

from ptwin.physics.hereditary import _Geometry, _Substitution, hereditary_inverse
from ptwin.physics.recurrence import relaxation_integral


def irregular_curve(samples: int, modes: int, seed: int):
    """Times with a flat step (repeated times, as on a reference's depth nodes), a noisy force, modes' times
    over three decades and their weights."""
    generator = torch.Generator().manual_seed(seed)
    time = torch.cumsum(torch.rand(samples, generator=generator, dtype=torch.float64) * 0.02, 0)
    time[samples // 4] = time[samples // 4 - 1]
    force = (time - time[0]) ** 1.5 + 1e-3 * torch.randn(samples, generator=generator, dtype=torch.float64)
    times = torch.logspace(-2, 1, modes, dtype=torch.float64)
    weights = torch.rand(modes, generator=generator, dtype=torch.float64)
    return time, force, times, weights, torch.tensor(0.2, dtype=torch.float64)


def hereditary_operator(force, extra, weights, times, time):
    """F + extra·(F − F₀) + Σ_m w_m q_m(F), what ``hereditary_inverse`` inverts, one relaxation integral a mode."""
    start = torch.arange(time.numel()) == 0
    memory = sum(w * relaxation_integral(force, t.expand_as(time), time, start) for w, t in zip(weights, times))
    return force + extra * (force - force[0]) + memory


@pytest.mark.parametrize("modes", [1, 3, 40])
def test_hereditary_inverse_inverts_the_relaxation_whatever_the_block(modes):
    """F + extra·(F − F₀) + Σ w_m q_m(F) = target, solved block by block: the blocks are a matter of cost (the
    default takes one block for one mode's 200 samples), never of the answer."""
    time, force, times, weights, extra = irregular_curve(200, modes, modes)
    target = hereditary_operator(force, extra, weights, times, time)
    for block in (None, 7, 200):
        recovered = hereditary_inverse(target, extra, weights, times, time, block)
        torch.testing.assert_close(recovered, force, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("block", [1, 7, 100])
def test_the_adjoint_solve_is_the_dense_transposes(block):
    # The operator's matrix column by column (it is linear in F), transposed and solved densely.
    time, _, times, weights, extra = irregular_curve(40, 3, 1)
    operator = torch.stack([hereditary_operator(e, extra, weights, times, time) for e in torch.eye(40).double()], 1)
    cotangent = torch.randn(40, dtype=torch.float64, generator=torch.Generator().manual_seed(2))
    blocks = _Substitution(extra, weights, _Geometry(times, time, block))
    expected = torch.linalg.solve(operator.T, cotangent)
    torch.testing.assert_close(blocks.solve_transposed(cotangent), expected, rtol=1e-10, atol=1e-12)
    torch.testing.assert_close(blocks.solve(cotangent), torch.linalg.solve(operator, cotangent), rtol=1e-10, atol=0)


@pytest.mark.parametrize("block", [None, 4])
def test_derivatives_in_every_input_first_and_second_order(block):
    """LM's Jacobians differentiate a gradient (``ptwin.fitting.lm.Traced``): both orders against finite
    differences, in the target, the extra factor, the weights and the modes' times, across blocks."""
    time, force, times, weights, extra = irregular_curve(13, 2, 3)
    target = hereditary_operator(force, extra, weights, times, time)
    inputs = [x.clone().requires_grad_(True) for x in (target, extra, weights, times)]

    def inverse(target, extra, weights, times):
        return hereditary_inverse(target, extra, weights, times, time, block)

    assert torch.autograd.gradcheck(inverse, inputs)
    assert torch.autograd.gradgradcheck(inverse, inputs)
    # Modes whose times are held (a power law's): their decays come from the kept geometry, no slope in them.
    held = times.detach()
    assert torch.autograd.gradgradcheck(lambda *x: inverse(*x, held), inputs[:3])


def test_a_kept_geometry_is_reused_only_while_its_times_are_the_same():
    """A fit solves on the same samples at every step; a power law's modes keep their times, a relaxation's move.
    What is kept must never answer for other times: each solve equals a fresh one."""
    from ptwin.physics.hereditary import KeptGeometry

    time, force, times, weights, extra = irregular_curve(60, 3, 4)
    kept = KeptGeometry()

    def solved(times, weights):
        target = hereditary_operator(force, extra, weights, times, time)
        recovered = hereditary_inverse(target, extra, weights, times, time, kept=kept)
        torch.testing.assert_close(recovered, force, rtol=1e-10, atol=1e-12)
        return kept.geometry(times, time, max(1000 // times.numel(), 25))

    first = solved(times, weights)
    assert solved(times.clone(), 2 * weights) is first  # new weights, equal times: the same geometry
    assert solved(times * 1.5, weights) is not first  # times that moved: built again
    moved = solved(times, weights)
    time *= 1.5  # written in place: the samples are not what it was built on
    assert solved(times, weights) is not moved
