"""The dimensions of a separated problem: what each 1-D (or 2-D) factor space can do.

Every operator term is a tensor product over dimensions, so the greedy solver needs
from each dimension only: apply term t to factors, solve a weighted sum of its term
operators, and give its load vector. FE dimensions hold sparse P1 matrices; parameter
dimensions are diagonal (coefficient × quadrature weight at each grid node).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg
import torch


def solve_tridiagonal(matrix: sp.spmatrix, rhs: np.ndarray) -> np.ndarray:
    """O(N) solve of a tridiagonal sparse system (the 1-D P1 problems)."""
    bands = np.zeros((3, matrix.shape[0]))
    bands[0, 1:] = matrix.diagonal(1)
    bands[1] = matrix.diagonal(0)
    bands[2, :-1] = matrix.diagonal(-1)
    return scipy.linalg.solve_banded((1, 1), bands, rhs)


@dataclass
class FEDimension:
    """A P1 FE dimension whose term operators are combinations a·stiffness + b·mass.

    Args:
        name: dimension name ("plane" or "thickness").
        stiffness, mass: (N, N) sparse matrices on the free nodes.
        term_weights: (T, 2) tensor, term t is ``w[t,0]·stiffness + w[t,1]·mass``.
        load: (N,) load vector of the right-hand side.
        banded: True for a 1-D (tridiagonal) dimension, solved in O(N).
    """

    name: str
    stiffness: sp.csr_matrix
    mass: sp.csr_matrix
    term_weights: torch.Tensor
    load: torch.Tensor
    banded: bool

    @property
    def size(self) -> int:
        return self.stiffness.shape[0]

    def diagonal(self) -> torch.Tensor:
        """Diagonal of Σ_t A_t (the Jacobi scaling of the residual)."""
        a, b = self.term_weights.sum(dim=0).tolist()
        return torch.from_numpy(a * self.stiffness.diagonal() + b * self.mass.diagonal())

    def apply(self, term: int, factors: torch.Tensor) -> torch.Tensor:
        """Term operator applied to factors (N, n) -> (N, n)."""
        a, b = self.term_weights[term].tolist()
        dense = factors.numpy()
        return torch.from_numpy(a * (self.stiffness @ dense) + b * (self.mass @ dense))

    def solve(self, coefficients: torch.Tensor, rhs: torch.Tensor) -> torch.Tensor:
        """Solve (Σ_t coefficients[t]·A_t) f = rhs for one vector f (N,)."""
        a, b = (coefficients @ self.term_weights).tolist()
        matrix = (a * self.stiffness + b * self.mass).tocsc()
        if self.banded:
            solution = solve_tridiagonal(matrix, rhs.numpy())
        else:
            solution = scipy.sparse.linalg.spsolve(matrix, rhs.numpy())
        return torch.from_numpy(np.asarray(solution, dtype=np.float64))


@dataclass
class ParameterDimension:
    """A parameter dimension on a log-uniform grid; its term operators are diagonal.

    Args:
        name: parameter name ("velocity", "permeability", ...).
        nodes: (N,) grid values in SI units, log-uniform.
        term_coefficients: (T, N) diagonal of each term, quadrature weight included.
        load: (N,) right-hand side, quadrature weight included.
    """

    name: str
    nodes: torch.Tensor
    term_coefficients: torch.Tensor
    load: torch.Tensor

    @property
    def size(self) -> int:
        return self.nodes.numel()

    def diagonal(self) -> torch.Tensor:
        return self.term_coefficients.sum(dim=0)

    def apply(self, term: int, factors: torch.Tensor) -> torch.Tensor:
        return self.term_coefficients[term, :, None] * factors

    def solve(self, coefficients: torch.Tensor, rhs: torch.Tensor) -> torch.Tensor:
        return rhs / (coefficients @ self.term_coefficients)
