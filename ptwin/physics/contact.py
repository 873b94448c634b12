"""Each curve's contact point as a nuisance of the fit (``contact_point: estimate``).

Every contact was estimated from its curve (``ptwin.data.contact``); the reference
curve's estimate is the origin of depth (the elastic law is read off it), and the fit
refines every other curve's contact relative to it: curve c's depth is w − offset_c, for
the elastic law and the fluid alike. The reference's own correction is not fitted: it
enters the fluid only, so a fit can move it by the whole indentation and switch the
Darcy force off (seen on a soft-cantilever set: 0.77 µm of 0.7 µm) — a nuisance the data
do not pin down is not a refinement.
"""

from __future__ import annotations

import torch
from torch import nn

from ptwin.physics.samples import Samples


class ContactNuisance(nn.Module):
    """Contact-point corrections [m]: ``offsets``, one per fitted curve in ``curve_ids`` order."""

    def __init__(self, curve_ids: tuple[str, ...]):
        super().__init__()
        self.curve_ids = tuple(curve_ids)
        self.offsets = nn.Parameter(torch.zeros(len(curve_ids), dtype=torch.float64))

    def shift(self, samples: Samples) -> torch.Tensor:
        """What to subtract from each sample's depth [m]: its curve's correction. Samples of curves after
        the fitted ones (a simulated next experiment, its contact known) get none, and so do samples
        whose curves are not the fitted ones at all (the reference's depth nodes)."""
        count = len(self.curve_ids)
        if samples.curve_ids[:count] != self.curve_ids:
            return torch.zeros_like(samples.depth)
        extra = torch.zeros(len(samples.curve_ids) - count, dtype=self.offsets.dtype, device=self.offsets.device)
        return torch.cat([self.offsets, extra])[samples.curve]

    def values(self) -> dict[str, float]:
        """The corrections [m] by curve id."""
        return {curve: value.item() for curve, value in zip(self.curve_ids, self.offsets)}
