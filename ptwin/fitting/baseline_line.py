"""The error of each curve's removed baseline line, carried into a fit's residual by projection.

Where contacts are estimated, each curve's baseline line (level and tilt, ``ptwin.data.contact``) is fitted to
its free travel and removed from the whole curve. Its error is a line in the travel t: δ_level + δ_tilt·t,
extrapolated from a baseline of about a micron over an indentation of several: on a simulated null (0.3 nN of
white noise, 1 µm of baseline, 4 µm of travel) the removed tilts were off by up to 0.72 nN at the deepest
sample, a misfit over hundreds of samples that no noise model of the residual holds. A fit read it as
evidence: the reference's contact correction, which acts on the deep rate forces, moved 55 nm from the truth
for a χ² gain of 60 (its Wald z +9.3), and the contact bench's held corrections moved on every null that held
one.

The line's error is a nuisance the fit can estimate with everything else, pinned by the baseline it came from:
minimising ‖r + X u‖² + uᵀΛu over u (X = [1, t] at the fitted samples, Λ = X_bᵀX_b of the baseline's samples,
both in noise units: the baseline samples fitted beside the curve, where their residual from the line is
orthogonal to it) leaves rᵀ(I − X A⁻¹ Xᵀ)r, A = XᵀX + Λ. The fit minimises ‖L r‖² with LᵀL = I − X A⁻¹ Xᵀ:
with X = Q R (thin QR) and S = R A⁻¹ Rᵀ (eigenvalues in [0, 1)), L = I − Q (I − (I − S)^½) Qᵀ, a rank-two
update of each curve's residual, linear, so LM's Jacobian is L J and nothing else changes. The reference's
line error is one more nuisance, shared: the elastic law read off its approach carries it into every other
curve with the opposite sign, so X is D = [blocks of each curve's X_c | −X_c stacked], and S, of the size of
two columns a curve, couples the curves (``_nuisances``). Where the set's common level was removed (the levels
are one level plus drag), only the tilt is a nuisance, with the precision of a slope whose level is unknown.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from ptwin.physics.samples import Samples


class BaselineLines:
    """The removed lines' errors as nuisances of a fit to ``samples[index]``: ``project`` (L, on those rows) for
    the fit, ``fitted`` (the lines it implies, at every sample) for what it leaves. ``of`` gives None where no
    curve of ``index`` had a line removed."""

    def __init__(self, samples: Samples, read: tuple[np.ndarray, ...], lined: list[int], own_level: bool):
        """``read``: (curve, travel, line sums) of the fit's samples, as ``of`` read them."""
        curves, travel, sums = read
        self.scale = float(np.abs(travel).max()) or 1.0  # t in units of the deepest travel: A is well conditioned
        self.lined, self.own_level = lined, own_level
        rows = [np.flatnonzero(curves == c) for c in lined]
        factors = [np.linalg.qr(_design(travel[r] / self.scale, own_level)) for r in rows]
        precisions = [_precision(sums[r[0]], self.scale, own_level) for r in rows]
        reference = samples.reference_line
        shared = None if reference is None else _precision(np.asarray(reference), self.scale, own_level)
        mapping, prior = _nuisances([r for _, r in factors], precisions, shared)
        solve = np.linalg.solve(mapping.T @ mapping + prior, mapping.T)
        s = mapping @ solve
        values, vectors = np.linalg.eigh((s + s.T) / 2)
        shrink = vectors @ np.diag(1.0 - np.sqrt(np.clip(1.0 - values, 0.0, 1.0))) @ vectors.T
        self.width = factors[0][0].shape[1]
        basis = np.zeros((curves.size, self.width))
        position = np.zeros(curves.size, dtype=np.int64)
        for i, (r, (q, _)) in enumerate(zip(rows, factors)):
            basis[r], position[r] = q, i
        device, dtype = samples.travel.device, samples.travel.dtype
        self._basis, self._shrink, self._solve = (
            torch.from_numpy(a).to(device=device, dtype=dtype) for a in (basis, shrink, solve)
        )
        self._position = torch.from_numpy(position).to(device)
        self._samples = samples

    @classmethod
    def of(cls, samples: Samples, index: torch.Tensor) -> BaselineLines | None:
        curves, sums = (a[index].cpu().numpy() for a in (samples.curve, samples.line_sums))
        lined = [int(c) for c in np.unique(curves) if sums[np.argmax(curves == c), 0] > 0]
        if not lined:
            return None
        own_level = bool(samples.own_level[index][int(np.argmax(curves == lined[0]))])
        lined = [c for c in lined if np.count_nonzero(curves == c) > 1 + own_level]  # more samples than a line has
        if not lined:
            return None
        return cls(samples, (curves, samples.travel[index].cpu().numpy(), sums), lined, own_level)

    def _coefficients(self, r: torch.Tensor) -> torch.Tensor:
        """Qᵀ r, each lined curve's basis on its rows: (curves·width, trailing)."""
        flat = r.reshape(r.shape[0], -1)
        coefficients = torch.zeros(len(self.lined), self.width, flat.shape[1], dtype=r.dtype, device=r.device)
        coefficients = coefficients.index_add(0, self._position, self._basis[:, :, None] * flat[:, None, :])
        return coefficients.reshape(len(self.lined) * self.width, -1)

    def project(self, r: torch.Tensor) -> torch.Tensor:
        """L r: ``r`` on the fit's rows (a residual in noise units, or its Jacobian, rows first) with the lines'
        errors fitted out under their baselines' precision; ‖L r‖² is the fit's cost."""
        shrunk = (self._shrink @ self._coefficients(r)).reshape(len(self.lined), self.width, -1)
        correction = (self._basis[:, :, None] * shrunk[self._position]).sum(dim=1)
        return (r.reshape(r.shape[0], -1) - correction).reshape(r.shape)

    def fitted(self, r: torch.Tensor) -> torch.Tensor:
        """The lines' errors the fit's residual ``r`` (noise units, on its rows) implies, at every sample (noise
        units; 0 on curves without a line or without samples in the fit): what a residual less them leaves is the
        residual the fit minimised."""
        nuisances = -(self._solve @ self._coefficients(r)).reshape(-1, self.width)  # û = −(DᵀD + P)⁻¹ Dᵀ r
        shared = nuisances[len(self.lined)] if nuisances.shape[0] > len(self.lined) else torch.zeros_like(nuisances[0])
        samples, device = self._samples, self._samples.curve.device
        lookup = torch.full((len(samples.curve_ids),), -1, dtype=torch.long, device=device)
        lookup[torch.tensor(self.lined, device=device)] = torch.arange(len(self.lined), device=device)
        mine = lookup[samples.curve]
        columns = torch.from_numpy(_design(samples.travel.cpu().numpy() / self.scale, self.own_level)).to(r)
        own = nuisances[mine.clamp(min=0)] - shared
        return torch.where(mine >= 0, (columns * own).sum(dim=1), torch.zeros_like(samples.travel))


def line_projection(samples: Samples, index: torch.Tensor) -> Callable[[torch.Tensor], torch.Tensor]:
    """r ↦ L r on ``samples[index]`` (``BaselineLines.project``); r itself where no curve had a line removed."""
    lines = BaselineLines.of(samples, index)
    return (lambda r: r) if lines is None else lines.project


def _design(t: np.ndarray, own_level: bool) -> np.ndarray:
    """The line's columns at travel ``t``: level and tilt, or the tilt alone (the set's common level removed)."""
    return np.column_stack([np.ones_like(t), t]) if own_level else t[:, None]


def _precision(sums: np.ndarray, scale: float, own_level: bool) -> np.ndarray:
    """Xᵀ X of a baseline's samples from their (n, Σt, Σt²), t in units of ``scale``: the precision of its line
    in noise units; of its slope alone, its level unknown, where the common level was removed."""
    n, total, square = sums[0], sums[1] / scale, sums[2] / scale**2
    return np.array([[n, total], [total, square]]) if own_level else np.array([[square - total**2 / n]])


def _nuisances(
    factors: list[np.ndarray], precisions: list[np.ndarray], shared: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """(R, P): R maps the nuisances (each curve's line, then the reference's, shared by every curve with the
    opposite sign: the law read off the reference carries its error into each) onto the curves' stacked bases
    (D = Q R), P is their prior precision."""
    width, count = factors[0].shape[0], len(factors)
    unknowns = count + (shared is not None)
    mapping = np.zeros((count * width, unknowns * width))
    prior = np.zeros((unknowns * width, unknowns * width))
    for i, (r, p) in enumerate(zip(factors, precisions)):
        block = slice(i * width, (i + 1) * width)
        mapping[block, block], prior[block, block] = r, p
        if shared is not None:
            mapping[block, count * width :] = -r
    if shared is not None:
        prior[count * width :, count * width :] = shared
    return mapping, prior
