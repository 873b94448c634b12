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
        """What to subtract from each sample's depth [m]: its curve's correction, found by curve id (a fit
        of one curve sees it alone). Curves that are not fitted ones get none: the reference curve (its
        depth nodes) and a simulated next experiment, whose contact is known."""
        position = {curve: i for i, curve in enumerate(self.curve_ids)}
        none = len(self.curve_ids)
        lookup = torch.tensor([position.get(curve, none) for curve in samples.curve_ids], device=samples.curve.device)
        extra = torch.zeros(1, dtype=self.offsets.dtype, device=self.offsets.device)
        return torch.cat([self.offsets, extra])[lookup[samples.curve]]

    def values(self) -> dict[str, float]:
        """The corrections [m] by curve id."""
        return {curve: value.item() for curve, value in zip(self.curve_ids, self.offsets)}
