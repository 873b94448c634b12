"""Locate the mismatch: where residuals rise above the noise floor, and whether they
are structure or noise.

The whiteness statistic of a curve splits its residual (in noise units, time order)
into blocks of ``block`` samples: for white noise each block mean has variance
1/block, so W = mean(block · mean²) ≈ 1; structure that persists over a block
inflates it by the block length. Correlated noise inflates it too, by κ² (the noise
model's block-mean variance over the white expectation), so W is divided by κ²: the set's, or a
curve's own where its baseline measured more (``Samples.curve_inflation``). Noise alone
still reads above 1 (the elastic law is read off a noisy curve); what it reads, and so the
threshold, is ``ptwin.diagnosis.null``'s.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch

from ptwin.physics.samples import Samples

if TYPE_CHECKING:
    from ptwin.diagnosis.null import StructureTest


@dataclass
class Mismatch:
    curve: str
    base_speed: float  # [m/s]
    depth_from: float  # [m] first and last depth of the blocks off the noise floor
    depth_to: float
    rms_residual: float  # [N] over that range
    noise_floor: float  # [N], the RMS of the residual noise std over that range
    whiteness: float  # W of the curve's whole residual
    span: int = 0  # recorded samples of the curve from the range's first to its last


def block_means(scaled: torch.Tensor, block: int) -> torch.Tensor:
    """Means of consecutive blocks of ``block`` samples (a short tail joins the last block)."""
    count = max(scaled.numel() // block, 1)
    edges = torch.linspace(0, scaled.numel(), count + 1, device=scaled.device).long()
    return torch.stack([scaled[a:b].mean() for a, b in zip(edges[:-1], edges[1:])]), edges


def whiteness(scaled: torch.Tensor, block: int, inflation: float = 1.0) -> float:
    """W = mean over blocks of n_b·mean_b² / κ² for a residual in noise units (≈ 1 for noise of
    block-mean variance inflation κ² = ``inflation``)."""
    means, edges = block_means(scaled, block)
    return (torch.diff(edges) * means.square()).mean().item() / inflation


def pooled_whiteness(samples: Samples, residual: torch.Tensor, index: torch.Tensor, block: int) -> float:
    """W over the blocks of every curve (``residual`` in N, on ``index``, time-ordered), in units of the
    samples' noise model."""
    parts = [_curve_residual(samples, residual, index, i) for i in range(len(samples.curve_ids))]
    values = [whiteness(scaled, block, _inflation(samples, where)) for scaled, where in parts if scaled.numel()]
    return sum(values) / len(values)


def _inflation(samples: Samples, where: torch.Tensor) -> float:
    """κ² of the curve of the samples ``where`` (its own where its baseline measured more than the set's)."""
    return samples.curve_inflation[where[0]].item()


def _curve_residual(samples, residual, index, curve):
    mine = samples.curve[index] == curve
    return residual[mine] / samples.noise_floor[index][mine], index[mine]


def locate(samples: Samples, residual: torch.Tensor, index: torch.Tensor, block: int, test: StructureTest):
    """Per curve, the depth range where the residual (N, on ``index``) is structure above the noise.

    A curve is listed when its whiteness exceeds its quantile under ``test``; its range spans the
    blocks whose mean is more than 3 standard errors off zero.
    """
    found = []
    for i, curve in enumerate(samples.curve_ids):
        scaled, where = _curve_residual(samples, residual, index, i)
        if scaled.numel() == 0:
            continue
        inflation = _inflation(samples, where)
        w = whiteness(scaled, block, inflation)
        if w <= test.curve_threshold(i):
            continue
        means, edges = block_means(scaled, block)
        off = (means.abs() * torch.diff(edges).sqrt() > 3.0 * inflation**0.5).nonzero().squeeze(1)
        if off.numel() == 0:
            continue
        lo, hi = edges[off.min()].item(), edges[off.max() + 1].item()
        depth, noise = samples.depth[where[lo:hi]], samples.noise_floor[where[lo:hi]]
        found.append(
            Mismatch(
                curve=curve,
                base_speed=samples.base_speed[where[0]].item(),
                depth_from=depth.min().item(),
                depth_to=depth.max().item(),
                rms_residual=(scaled[lo:hi] * noise).square().mean().sqrt().item(),
                noise_floor=noise.square().mean().sqrt().item(),
                whiteness=w,
                span=int(where[hi - 1] - where[lo]) + 1,  # a curve's samples lie together, in time order
            )
        )
    return found
