"""The factor spaces of the separated solver and the Galerkin pencil, against dense algebra."""

import numpy as np
import pytest
import torch

from ptwin.pgd.config import PlaneMesh
from ptwin.pgd.dimensions import _banded
from ptwin.pgd.enrichment import _pencil
from ptwin.pgd.fem import triangle_matrices
from ptwin.pgd.problem import build_problem
from tests.conftest import small_config


def dense_term(dim, term: int) -> torch.Tensor:
    return dim.apply(torch.eye(dim.size, dtype=torch.float64))[term]


def test_each_dimension_solves_its_weighted_operators():
    problem = build_problem(small_config())
    generator = torch.Generator().manual_seed(0)
    for dim in problem.dims:
        terms = [dense_term(dim, t) for t in range(problem.n_terms)]
        coefficients = torch.tensor([[0.3, 2.0], [5.0, 1e-3]], dtype=torch.float64)
        rhs = torch.rand(dim.size, generator=generator, dtype=torch.float64)
        for c in coefficients:
            matrix = c[0] * terms[0] + c[1] * terms[1]
            solution = dim.solve(c, rhs)
            # Backward error: the graded φ mesh (elements 1e-7 … 0.5) is far from well conditioned.
            scale = torch.linalg.matrix_norm(matrix, 2) * solution.norm() + rhs.norm()
            assert (matrix @ solution - rhs).norm() < 1e-13 * scale, dim.name
        each = dim.solve_each(coefficients)
        for i, c in enumerate(coefficients):
            assert torch.allclose(each[:, i], dim.solve(c, dim.load), rtol=1e-12, atol=0), dim.name


def test_in_plane_eigenbasis_integrates_over_the_disc_at_second_order():
    # A nodal field f has eigen-coefficients a = VᵀMf (V is M-orthonormal), and the
    # problem's top integral of it is load·a. For f = 1 − r² (zero on the rim) the
    # integral over the unit disc is π/2; P1 on a polygonal disc converges as h².
    errors, spacing = [], []
    for rings in (4, 8, 16):
        problem = build_problem(small_config(plane=PlaneMesh(rings=rings, edge_grading=1.0)))
        free = problem.plane_free
        _, mass = triangle_matrices(problem.plane_nodes, problem.plane_triangles)
        field = 1.0 - (problem.plane_nodes[free] ** 2).sum(axis=1)
        coefficients = problem.plane_modes.T @ torch.from_numpy(mass[free][:, free] @ field)
        errors.append(abs((problem.dims.plane.load @ coefficients).item() - np.pi / 2))
        spacing.append(1.0 / rings)
    order = np.polyfit(np.log(spacing), np.log(errors), 1)[0]
    assert errors[-1] < 1e-2
    assert order == pytest.approx(2.0, abs=0.3)


def test_pencil_drops_the_null_space_of_dependent_modes():
    generator = torch.Generator().manual_seed(0)
    modes = torch.rand(30, 4, generator=generator, dtype=torch.float64)
    modes = torch.cat([modes, modes[:, :1]], dim=1)  # a fifth mode equal to the first
    b0 = modes.T @ modes
    b1 = modes.T @ torch.diag(torch.linspace(1, 2, 30, dtype=torch.float64)) @ modes
    lam, w = _pencil(b1, b0 + b1)
    assert w.shape == (5, 4)
    assert torch.allclose(w.T @ (b0 + b1) @ w, torch.eye(4, dtype=torch.float64), atol=1e-10)
    assert torch.allclose(w.T @ b1 @ w, torch.diag(lam), atol=1e-10)
    assert ((lam >= 0) & (lam <= 1)).all()


def test_a_singular_tridiagonal_system_is_refused_in_words():
    with pytest.raises(np.linalg.LinAlgError, match="singular"):
        _banded(np.zeros((3, 4)), np.ones(4))
