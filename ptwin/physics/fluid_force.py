"""``FluidForce``: the Darcy fluid force from a frozen PGD basis, K learnable.

Out-of-range policy (never a silent wrong force):
- velocity, permeability, and contact radius in scaled coordinates, are exact power
  laws of the basis (checked at load), valid for any value: no range applies.
- contact radius below the grid (first contact, R → 0): the exact small-R law
  F(U, K, R, H) = (R/R_min)³ F(U, K, R_min, H·R_min/R), a consequence of
  F = c(H/R)·μ·U·R³/K; R = 0 gives F = 0.
- aspect ratio H/R above the grid: clamped to the grid's top (c(x) − c(∞) ∝ e^(−2 j₁ x)
  is below 1e-300 there); below the grid, or any other parameter off its grid:
  ``ValueError`` naming the parameter, the value, the range and the fix.
"""

from __future__ import annotations

import math
from pathlib import Path

import torch
from torch import nn

from ptwin.pgd.basis import Basis
from ptwin.physics.log_grid import LogGridFunctions


class FluidForce(nn.Module):
    """F_D = ∫_top P dA [N] for batches of (U [m/s], R [m], H [m]).

    The recompressed basis is held as frozen buffers; ``log_permeability`` is the only
    parameter. Build with ``FluidForce.load(path, permeability=2e-16, viscosity=1e-3)``.
    """

    def __init__(self, basis: Basis, permeability: float, viscosity: float):
        super().__init__()
        if not permeability > 0:
            raise ValueError(f"permeability must be > 0 m², got {permeability}")
        if not viscosity > 0:
            raise ValueError(f"viscosity must be > 0 Pa s, got {viscosity}")
        self.coordinates = basis.config.coordinates
        self.basis_hash = basis.config_hash
        self.names = list(basis.force.names)
        self.viscosity = float(viscosity)
        self.log_permeability = nn.Parameter(torch.tensor(math.log(permeability), dtype=torch.float64))
        self.functions = nn.ModuleList(
            LogGridFunctions(basis.grids[name][0], basis.grids[name][1], values)
            for name, values in zip(self.names, basis.force.functions)
        )
        self.register_buffer("core", basis.force.core)
        for name, function in zip(self.names, self.functions):
            if name == "contact_radius" and function.power_law is None and self.coordinates == "scaled":
                raise ValueError("basis: the contact-radius mode is not a power law; rebuild it")

    @classmethod
    def load(cls, path: str | Path, permeability: float = 2e-16, viscosity: float = 1e-3) -> FluidForce:
        return cls(Basis.load(path), permeability, viscosity)

    @property
    def permeability(self) -> torch.Tensor:
        """Current permeability K [m²]."""
        return self.log_permeability.exp()

    def forward(self, velocity: torch.Tensor, contact_radius: torch.Tensor, height: torch.Tensor) -> torch.Tensor:
        return self.evaluate(velocity, contact_radius, height, self.permeability)

    def evaluate(self, velocity, contact_radius, height, permeability) -> torch.Tensor:
        """The force for an explicit permeability [m²]: a scalar, or one per point of the batch."""
        shape = torch.broadcast_shapes(velocity.shape, contact_radius.shape, height.shape)
        u, r, h = (t.expand(shape).reshape(-1) for t in (velocity, contact_radius, height))
        smallest = self.functions[2].minimum
        scale = 1.0
        below = r < smallest
        if bool(below.any()):
            safe_r = torch.where(r > 0, r, torch.full_like(r, smallest))
            scale = torch.where(below, (r / smallest) ** 3, torch.ones_like(r))
            h = torch.where(below, h * smallest / safe_r, h)
            r = torch.where(below, torch.full_like(r, smallest), r)
        last = h / r if self.coordinates == "scaled" else h
        last = self._in_range(self.names[3], last, clamp_above=self.names[3] == "aspect_ratio")
        factors = [
            self.functions[0](u),
            self.functions[1](permeability.reshape(-1)),  # one K for the batch (or one per point)
            self.functions[2](self._in_range("contact_radius", r)),
            self.functions[3](last),
        ]
        if self.core.numel() == 1:
            value = self.core.reshape(()) * factors[0][:, 0] * factors[1][:, 0] * factors[2][:, 0] * factors[3][:, 0]
        else:
            batch = [f.expand(u.numel(), -1) for f in factors]
            value = torch.einsum("abcd,na,nb,nc,nd->n", self.core, *batch)
        return (self.viscosity * scale * value).reshape(shape)

    def _in_range(self, name: str, values: torch.Tensor, clamp_above: bool = False) -> torch.Tensor:
        function = self.functions[self.names.index(name)]
        if function.power_law is not None:
            return values
        low, high = values.min().item(), values.max().item()
        grid = f"[{function.minimum:.3g}, {function.maximum:.3g}]"
        if low < function.minimum * (1 - 1e-12):
            raise ValueError(
                f"FluidForce: {name} {low:.3g} is below the basis grid {grid}; "
                f"rebuild the basis with a smaller pgd.{name}.minimum"
            )
        if clamp_above:
            return values.clamp(max=function.maximum)
        if high > function.maximum * (1 + 1e-12):
            raise ValueError(
                f"FluidForce: {name} {high:.3g} is above the basis grid {grid}; "
                f"rebuild the basis with a larger pgd.{name}.maximum"
            )
        return values
