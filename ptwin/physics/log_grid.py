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
            # An integer exponent that fits as well is the physics (U¹, K⁻¹, R³) and is cheaper.
            for candidate in (round(exponent), exponent):
                prefactor = np.exp(np.mean(np.log(np.abs(samples[:, 0])) - candidate * np.log(nodes)))
                fitted = prefactor * nodes**candidate
                if np.max(np.abs(fitted / np.abs(samples[:, 0]) - 1)) < POWER_LAW_TOL:
                    self.power_law = (float(np.sign(samples[0, 0]) * prefactor), candidate)
                    break
        signs = np.sign(samples)
        self.logarithmic = bool(np.all(signs != 0) and np.all(signs == signs[:1]))
        table = np.log(np.abs(samples)) if self.logarithmic else samples
        slopes = scipy.interpolate.CubicSpline(np.log(nodes), table, axis=0).derivative()(np.log(nodes)) * self.step
        # Cubic Hermite on each interval as a Horner polynomial in t ∈ [0, 1]: one gather per point.
        y0, y1, d0, d1 = table[:-1], table[1:], slopes[:-1], slopes[1:]
        cubic = np.stack([2 * y0 - 2 * y1 + d0 + d1, -3 * y0 + 3 * y1 - 2 * d0 - d1, d0, y0], axis=-1)
        self.register_buffer("cubic", torch.from_numpy(cubic))  # (N-1, r, 4)
        self.register_buffer("signs", torch.from_numpy(signs[0].copy()))

    @property
    def rank(self) -> int:
        return self.cubic.shape[1]

    def forward(self, p: torch.Tensor) -> torch.Tensor:
        """(B,) parameter values -> (B, r) function values. Range checks are the caller's."""
        if self.power_law is not None:
            prefactor, exponent = self.power_law
            if isinstance(exponent, int):
                return (prefactor * p**exponent)[:, None]
            return (prefactor * torch.sign(p) * p.abs() ** exponent)[:, None]
        value = self._hermite(p)[0]
        return self.signs * torch.exp(value) if self.logarithmic else value

    def log_and_slope(self, p: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """log|g_k(p)| and its log–log slope d log|g_k| / d log p, (B, r) each, for a
        table of one-signed functions: the derivative comes with the value, in closed form."""
        value, a, b, c, t = self._hermite(p)
        return value, ((3 * a * t + 2 * b) * t + c) / self.step

    def _hermite(self, p: torch.Tensor):
        """The table's cubic at p (B, r), with its interval's leading coefficients a, b, c
        (B, r) and the local coordinate t (B, 1) for the derivative."""
        u = (torch.log(p) - math.log(self.minimum)) / self.step
        index = u.detach().floor().clamp(0, self.cubic.shape[0] - 1).long()
        a, b, c, d = self.cubic[index].unbind(-1)
        t = (u - index)[:, None]
        return ((a * t + b) * t + c) * t + d, a, b, c, t
