"""Meshes of the two FE dimensions: the unit disc (in-plane) and φ ∈ [0, 1] (thickness)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay


def unit_disc(rings: int, ring_density: float = 6.0, edge_grading: float = 1.0):
    """Triangulate the unit disc with concentric rings of nodes.

    Ring k (1..rings) sits at radius ``1 - (1 - k/rings)**edge_grading`` and carries
    ``round(ring_density * rings * r_k)`` nodes, so tangential spacing is uniform and a
    grading > 1 packs rings toward the rim r = 1, where the Dirichlet edge meets the
    loaded top and the pressure gradient is singular.

    Returns:
        nodes: (N, 2) coordinates; triangles: (T, 3) node indices;
        boundary: (N,) bool, True on the rim (P = 0 there).
    """
    points = [np.zeros((1, 2))]
    on_rim = [np.zeros(1, dtype=bool)]
    for k in range(1, rings + 1):
        radius = 1.0 - (1.0 - k / rings) ** edge_grading
        count = max(6, round(ring_density * rings * radius))
        theta = 2 * np.pi * (np.arange(count) + 0.5 * (k % 2)) / count
        points.append(radius * np.column_stack([np.cos(theta), np.sin(theta)]))
        on_rim.append(np.full(count, k == rings))
    nodes = np.vstack(points)
    triangles = Delaunay(nodes).simplices
    return nodes, triangles, np.concatenate(on_rim)


def graded_thickness(nodes: int, finest: float) -> np.ndarray:
    """Nodes of φ ∈ [0, 1], geometrically graded toward the loaded top φ = 1.

    The pressure decays below the top over a depth ~R, i.e. Δφ ~ 1/x with x = H/R up
    to 1e5, so the spacing grows geometrically from ``finest`` at φ = 1 to the bottom.
    """
    depth_below_top = np.concatenate([[0.0], np.geomspace(finest, 1.0, nodes - 1)])
    return np.sort(1.0 - depth_below_top)
