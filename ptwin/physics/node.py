"""An autograd node without ``torch.autograd.Function.apply``'s signature binding on every call.

A Function that defines ``setup_context`` (the style torch.func's transforms need) has ``apply`` bind its
arguments to ``forward``'s signature by ``inspect`` on every call before it reaches the C++ node. That costs
tens of µs a call, a tenth of a relaxation or power-law fit's Jacobian on a map's spot, whose nodes are
applied some twenty times per Jacobian. ``Node.apply`` goes to the C++ node at once outside torch.func's
transforms, and is ``Function.apply`` inside them. Arguments are positional: there are no defaults to bind.
"""

from __future__ import annotations

import torch


class Node(torch.autograd.Function):
    """``torch.autograd.Function`` whose ``apply`` skips the binding outside torch.func's transforms."""

    @classmethod
    def apply(cls, *args):
        if torch._C._are_functorch_transforms_active():
            return super().apply(*args)
        return super(torch.autograd.Function, cls).apply(*args)  # what Function.apply calls once bound
