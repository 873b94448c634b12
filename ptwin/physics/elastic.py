"""Elastic laws of the solid network."""

from __future__ import annotations

import numpy as np


def hertz_force(depth: np.ndarray, effective_modulus: float, probe_radius: float) -> np.ndarray:
    """F = 4/3·E*·√ρ·w^1.5 [N] for depth w [m] (0 before contact)."""
    w = np.clip(depth, 0.0, None)
    return 4.0 / 3.0 * effective_modulus * np.sqrt(probe_radius) * w**1.5


def hertz_stiffness(depth: np.ndarray, effective_modulus: float, probe_radius: float) -> np.ndarray:
    """dF/dw = 2·E*·√(ρ w) [N/m]."""
    return 2.0 * effective_modulus * np.sqrt(probe_radius * np.clip(depth, 0.0, None))
