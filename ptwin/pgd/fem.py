"""P1 finite-element matrices of the two FE dimensions (scipy sparse, float64)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def triangle_matrices(nodes: np.ndarray, triangles: np.ndarray):
    """Stiffness ∫∇u·∇v and mass ∫uv of P1 elements on a triangle mesh.

    Returns (stiffness, mass) as (N, N) CSR matrices.
    """
    corners = nodes[triangles]  # (T, 3, 2)
    edge1 = corners[:, 1] - corners[:, 0]
    edge2 = corners[:, 2] - corners[:, 0]
    doubled_area = edge1[:, 0] * edge2[:, 1] - edge1[:, 1] * edge2[:, 0]
    area = 0.5 * np.abs(doubled_area)
    # Gradients of the barycentric functions: rotate the opposite edge by 90°.
    opposite = np.stack(
        [corners[:, 2] - corners[:, 1], corners[:, 0] - corners[:, 2], corners[:, 1] - corners[:, 0]],
        axis=1,
    )
    gradients = np.stack([-opposite[..., 1], opposite[..., 0]], axis=-1) / doubled_area[:, None, None]
    local_stiffness = area[:, None, None] * np.einsum("tid,tjd->tij", gradients, gradients)
    local_mass = area[:, None, None] * (np.ones((3, 3)) + np.eye(3)) / 12.0
    return _assemble(triangles, local_stiffness, len(nodes)), _assemble(triangles, local_mass, len(nodes))


def interval_matrices(nodes: np.ndarray):
    """Stiffness and mass of P1 elements on sorted 1-D nodes, as (N, N) CSR matrices."""
    length = np.diff(nodes)
    cells = np.column_stack([np.arange(len(length)), np.arange(1, len(nodes))])
    local_stiffness = np.array([[1.0, -1.0], [-1.0, 1.0]]) / length[:, None, None]
    local_mass = np.array([[2.0, 1.0], [1.0, 2.0]]) * length[:, None, None] / 6.0
    return _assemble(cells, local_stiffness, len(nodes)), _assemble(cells, local_mass, len(nodes))


def _assemble(cells: np.ndarray, local: np.ndarray, size: int) -> sp.csr_matrix:
    rows = np.repeat(cells, cells.shape[1], axis=1).ravel()
    cols = np.tile(cells, (1, cells.shape[1])).ravel()
    return sp.csr_matrix((local.ravel(), (rows, cols)), shape=(size, size))
