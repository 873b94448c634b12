"""Functions of one parameter sampled on a log-uniform grid, evaluated in torch.

Power-law modes (U¹, K⁻¹, R³) are what the PGD produces along the separable
dimensions; linear interpolation of them caps accuracy at Δ²/8 with O(Δ) gradients.
So: a rank-1 function that *is* a power law to ``POWER_LAW_TOL`` is evaluated as that
law exactly (everywhere: it is the physics, e.g. linearity in U); the others by cubic
Hermite in s = log p, on log|g| when every function keeps one sign (exact for power
laws, C¹ gradients), with the not-a-knot spline slopes.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.interpolate
import torch
from torch import nn

POWER_LAW_TOL = 1e-9


class LogGridFunctions(nn.Module):
    """r functions g_k(p) of a parameter p > 0 from samples on a log-uniform grid.

    Args:
        minimum, maximum: grid range [SI unit of p].
        values: (N, r) samples at the N log-uniform nodes.
    """

    def __init__(self, minimum: float, maximum: float, values: torch.Tensor):
        super().__init__()
        self.minimum, self.maximum = float(minimum), float(maximum)
        nodes = np.geomspace(minimum, maximum, values.shape[0])
        samples = values.numpy()
        self.step = math.log(maximum / minimum) / (values.shape[0] - 1)
        self.power_law = None
        if samples.shape[1] == 1 and np.all(samples != 0) and len(np.unique(np.sign(samples))) == 1:
            exponent, log_prefactor = np.polyfit(np.log(nodes), np.log(np.abs(samples[:, 0])), 1)
            fitted = np.exp(log_prefactor) * nodes**exponent
            if np.max(np.abs(fitted / np.abs(samples[:, 0]) - 1)) < POWER_LAW_TOL:
                self.power_law = (float(np.sign(samples[0, 0]) * np.exp(log_prefactor)), float(exponent))
        signs = np.sign(samples)
        self.logarithmic = bool(np.all(signs != 0) and np.all(signs == signs[:1]))
        table = np.log(np.abs(samples)) if self.logarithmic else samples
        slopes = scipy.interpolate.CubicSpline(np.log(nodes), table, axis=0).derivative()(np.log(nodes))
        self.register_buffer("table", torch.from_numpy(table))
        self.register_buffer("slopes", torch.from_numpy(slopes * self.step))
        self.register_buffer("signs", torch.from_numpy(signs[0].copy()))

    @property
    def rank(self) -> int:
        return self.table.shape[1]

    def forward(self, p: torch.Tensor) -> torch.Tensor:
        """(B,) parameter values -> (B, r) function values. Range checks are the caller's."""
        if self.power_law is not None:
            prefactor, exponent = self.power_law
            return (prefactor * torch.sign(p) * p.abs() ** exponent)[:, None]
        u = (torch.log(p) - math.log(self.minimum)) / self.step
        index = u.detach().floor().clamp(0, self.table.shape[0] - 2).long()
        t = (u - index)[:, None]
        y0, y1 = self.table[index], self.table[index + 1]
        d0, d1 = self.slopes[index], self.slopes[index + 1]
        t2, t3 = t * t, t * t * t
        value = (2 * t3 - 3 * t2 + 1) * y0 + (t3 - 2 * t2 + t) * d0 + (-2 * t3 + 3 * t2) * y1 + (t3 - t2) * d1
        return self.signs * torch.exp(value) if self.logarithmic else value
