"""Each curve's contact point as a nuisance of the fit (``contact_point: estimate``).

Every contact was estimated from its curve (``ptwin.data.contact``); the reference
curve's estimate is the origin of the elastic law's depth axis (the law is read off the
reference's measured depths), and the fit refines every other curve's contact relative
to it: curve c's depth is w − offset_c, for the elastic law and the fluid alike.

The reference's own estimate can be off too: a force growing like √w from contact (a
solid viscosity, π·γ·U·√(ρw)) looks like an earlier contact to a Hertz onset (−66 nm on
real PAAm with 10 Pa·s added). The law read off the reference carries that shift with
it, so only the rate forces see its correction ``reference``: they are the reference's
force less its elastic part at the true depth, w − reference (and every other curve's
at w − offset_c − reference). Left at the estimate, the rate forces subtracted at the
reference's shallowest nodes have the wrong origin, and the fit reads a term that grows
like √w too large (γ 17.5 for 10.1 on that set; 10.1 with the correction fitted). What
pins it: the other curves' rate forces near contact and their pre-contact samples
(``CurveKinematics.pins_contact``), which must stay at the baseline. Where those are too small
to pin it, it is held: at its estimate, or later within ``reach`` where χ² falls there beyond
noise (``ptwin.fitting.physics_fit.later_contacts``); so it is too where it would move the
contact further than ``reach``, the reference's onset: the travel between its estimated
contact and where its force leaves the baseline for good (``Baseline.onset``). Within that
stretch the force is at the baseline's noise and a contact there is a matter of shape;
beyond it the recording itself says contact or no contact, and a correction that goes
there is a misfit of the model absorbed (a cantilever drag left out moved it 600 nm into
a 2.5 µm indentation, where the reference pushes back 80 nN). Held, it is still no known
contact: every profile interval refits it within that stretch on either side, and as far as
where the fit holds it (``ptwin.fitting.physics_fit.held_range``).
"""

from __future__ import annotations

import math

import torch
from torch import nn

from ptwin.physics.samples import Samples


class ContactNuisance(nn.Module):
    """Contact-point corrections [m]: ``offsets``, one per fitted curve in ``curve_ids`` order, relative to the
    reference curve's; ``reference``, the reference's own (the class docstring: it acts on the rate forces)."""

    def __init__(self, curve_ids: tuple[str, ...], reach: float = math.inf):
        super().__init__()
        self.curve_ids = tuple(curve_ids)
        self.reach = reach  # [m]: how far the reference's correction may go (its onset: the class docstring)
        self.offsets = nn.Parameter(torch.zeros(len(curve_ids), dtype=torch.float64))
        # Held at the estimate (not a free parameter) until a fit finds that the data fix it (``fit_physics``).
        self.reference = nn.Parameter(torch.zeros((), dtype=torch.float64), requires_grad=False)

    def shift(self, samples: Samples) -> torch.Tensor:
        """What to subtract from each sample's depth [m] for the elastic law: its curve's correction, found by
        curve id (a fit of one curve sees it alone). Curves that are not fitted ones get none: the reference
        curve (its depth nodes) and a simulated next experiment, whose contact is known."""
        position = {curve: i for i, curve in enumerate(self.curve_ids)}
        none = len(self.curve_ids)
        lookup = torch.tensor([position.get(curve, none) for curve in samples.curve_ids], device=samples.curve.device)
        extra = torch.zeros(1, dtype=self.offsets.dtype, device=self.offsets.device)
        return torch.cat([self.offsets, extra])[lookup[samples.curve]]

    def place(self, shifts: dict[str, float], reference: str) -> None:
        """Start from contacts ``shifts`` [m] later than the estimates, by curve id (``reference``: the reference
        curve's id): a fit of a term that grows as √w from contact starts where the onset read with that shape
        puts them (``Baseline.root_shift``)."""
        with torch.no_grad():
            for i, curve in enumerate(self.curve_ids):
                self.offsets[i] = shifts[curve] - shifts[reference]
            self.reference.fill_(shifts[reference])

    def move_reference(self, correction: float) -> None:
        """The reference's correction set to ``correction`` [m], every other curve's contact left where it is
        (theirs are relative to it): a start where the reference's contact is tried later than its estimate."""
        with torch.no_grad():
            self.offsets -= correction - self.reference
            self.reference.fill_(correction)

    def values(self) -> dict[str, float]:
        """The corrections [m] by curve id (the reference's relative ones)."""
        return {curve: value.item() for curve, value in zip(self.curve_ids, self.offsets)}
