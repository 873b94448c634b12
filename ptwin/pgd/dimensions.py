"""The dimensions of a separated problem: what each factor space can do.

Every operator term is a tensor product over dimensions, so the greedy solver needs
from each dimension only: apply every term to factors, solve a weighted sum of its
term operators (for one right-hand side, or for its load under many weightings), and
give its load vector. Two kinds cover the Darcy problem:

- ``DiagonalDimension``: every term operator is diagonal. Parameter grids are
  (coefficient × quadrature weight at each node); the in-plane P1 space becomes one in
  the eigenbasis of its stiffness–mass pencil (fast diagonalisation), where stiffness
  is diag(λ) and mass the identity. Solves are divisions.
- ``BandedDimension``: the 1-D P1 thickness space, tridiagonal, solved in O(N). Its
  graded mesh (elements from 1e-8 to 0.5) is far too ill-conditioned for a dense
  eigensolver, so it keeps its nodal basis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import torch


@dataclass
class DiagonalDimension:
    """A dimension whose term operators are diagonal.

    Args:
        name: dimension name ("plane", "velocity", "permeability", ...).
        term_coefficients: (T, N) diagonal of each term operator.
        load: (N,) right-hand side.
    """

    name: str
    term_coefficients: torch.Tensor
    load: torch.Tensor

    @property
    def size(self) -> int:
        return self.load.numel()

    def apply(self, factors: torch.Tensor) -> torch.Tensor:
        """Every term operator applied to factors (N, n) -> (T, N, n)."""
        return self.term_coefficients[:, :, None] * factors

    def solve(self, coefficients: torch.Tensor, rhs: torch.Tensor) -> torch.Tensor:
        """Solve (Σ_t coefficients[t]·A_t) f = rhs for one vector f (N,)."""
        return rhs / (coefficients @ self.term_coefficients)

    def solve_each(self, coefficients: torch.Tensor) -> torch.Tensor:
        """Solve (Σ_t coefficients[i, t]·A_t) z_i = load for each row i: (N, k)."""
        return self.load[:, None] / (coefficients @ self.term_coefficients).T


@dataclass
class ParameterDimension(DiagonalDimension):
    """A parameter on a log-uniform grid; ``nodes`` (N,) are its values in SI units."""

    nodes: torch.Tensor


@dataclass
class BandedDimension:
    """A 1-D P1 FE dimension whose term t is ``w[t,0]·stiffness + w[t,1]·mass``.

    Args:
        name: dimension name ("thickness").
        stiffness, mass: (N, N) tridiagonal sparse matrices.
        term_weights: (T, 2) weights of stiffness and mass in each term.
        load: (N,) right-hand side.
    """

    name: str
    stiffness: sp.spmatrix
    mass: sp.spmatrix
    term_weights: torch.Tensor
    load: torch.Tensor

    def __post_init__(self):
        # (T, 3, N) in scipy's solve_banded layout: upper, main and lower diagonals of each term.
        bands = np.stack([_bands(self.stiffness), _bands(self.mass)])
        self._term_bands = torch.from_numpy(np.einsum("tk,kbn->tbn", self.term_weights.numpy(), bands))

    @property
    def size(self) -> int:
        return self.load.numel()

    def apply(self, factors: torch.Tensor) -> torch.Tensor:
        """Every term operator applied to factors (N, n) -> (T, N, n)."""
        bands = self._term_bands[:, :, :, None]
        result = bands[:, 1] * factors
        result[:, :-1] += bands[:, 0, 1:] * factors[1:]
        result[:, 1:] += bands[:, 2, :-1] * factors[:-1]
        return result

    def solve(self, coefficients: torch.Tensor, rhs: torch.Tensor) -> torch.Tensor:
        """Solve (Σ_t coefficients[t]·A_t) f = rhs in O(N)."""
        matrix = np.einsum("t,tbn->bn", coefficients.numpy(), self._term_bands.numpy())
        return torch.from_numpy(_banded(matrix, rhs.numpy()))

    def solve_each(self, coefficients: torch.Tensor) -> torch.Tensor:
        """Solve (Σ_t coefficients[i, t]·A_t) z_i = load for each row i: (N, k)."""
        matrices = np.einsum("kt,tbn->kbn", coefficients.numpy(), self._term_bands.numpy())
        load = self.load.numpy()
        return torch.from_numpy(np.stack([_banded(matrix, load) for matrix in matrices], axis=1))


_TRIDIAGONAL = scipy.linalg.get_lapack_funcs("gtsv", (np.empty(0),))


def _banded(matrix: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """The tridiagonal system ``matrix`` (solve_banded's layout, a fresh array: overwritten) x = ``rhs`` by LAPACK's
    gtsv, which ``scipy.linalg.solve_banded`` calls for one band either side, without that wrapper's checks and
    conversions: the bands and loads are the mesh's, finite by construction, and the wrapper took three quarters
    of the solves' time in a basis build. The same call, so the same basis to the bit."""
    lower, diagonal, upper = matrix[2, :-1], matrix[1], matrix[0, 1:]
    *_, x, info = _TRIDIAGONAL(lower, diagonal, upper, rhs, overwrite_dl=1, overwrite_d=1, overwrite_du=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"a tridiagonal system of the basis is singular (LAPACK gtsv info {info})")
    return x


def _bands(matrix: sp.spmatrix) -> np.ndarray:
    bands = np.zeros((3, matrix.shape[0]))
    bands[0, 1:] = matrix.diagonal(1)
    bands[1] = matrix.diagonal(0)
    bands[2, :-1] = matrix.diagonal(-1)
    return bands
