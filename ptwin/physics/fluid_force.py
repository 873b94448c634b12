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
from ptwin.physics.node import Node


class _SeparableLaw(Node):
    """F = A·U·R³/K·c(x) [N] (A: μ and the laws' constants) as one autograd node, its derivatives in closed form.

    Scaled coordinates leave U, K and R exact power laws (U¹, K⁻¹, R³) and one shape
    function c of the aspect ratio x, whose log–log slope s the Hermite table gives with
    its value: ∂F/∂U = F/U, ∂F/∂R = 3F/R, ∂F/∂x = s·F/x, ∂F/∂K = −F/K. One node instead
    of ~30 small ones is what takes the layer past 1e7 evaluations per second forward
    and backward; ``jvp`` and the generated vmap rule keep it usable under torch.func's
    transforms too (the tests differentiate it by ``jacfwd`` against the generic layer).
    """

    generate_vmap_rule = True

    @staticmethod
    def forward(velocity, radius, aspect_ratio, permeability, shape, prefactor):
        log_c, slope = shape.log_and_slope(aspect_ratio)
        per_velocity = prefactor * radius**3 / permeability * torch.exp(log_c[:, 0])
        return velocity * per_velocity, per_velocity, slope[:, 0]

    @staticmethod
    def setup_context(ctx, inputs, output):
        radius, aspect_ratio, permeability = inputs[1:4]
        force, per_velocity, slope = output
        ctx.mark_non_differentiable(per_velocity, slope)
        saved = (force, per_velocity, slope, radius, aspect_ratio, permeability)
        ctx.save_for_backward(*saved)
        ctx.save_for_forward(*saved)

    @staticmethod
    def backward(ctx, grad, _per_velocity, _slope):
        force, per_velocity, slope, radius, aspect_ratio, permeability = ctx.saved_tensors
        weighted = grad * force
        needs = ctx.needs_input_grad
        return (
            grad * per_velocity if needs[0] else None,
            3 * weighted / radius if needs[1] else None,
            weighted * slope / aspect_ratio if needs[2] else None,
            (-weighted / permeability).sum_to_size(permeability.shape) if needs[3] else None,
            None,
            None,
        )

    @staticmethod
    def jvp(ctx, velocity, radius, aspect_ratio, permeability, _shape, _prefactor):
        force, per_velocity, slope, *values = ctx.saved_tensors
        relative = torch.zeros_like(force)
        for tangent, value, weight in zip((radius, aspect_ratio, permeability), values, (3.0, slope, -1.0)):
            if tangent is not None:
                relative = relative + weight * tangent / value
        tangent = force * relative
        if velocity is not None:
            tangent = tangent + per_velocity * velocity
        return tangent, None, None


class FluidInputError(ValueError):
    """An input the fluid layer cannot take; ``point`` is its index in the (flattened) batch."""

    def __init__(self, message: str, point: int):
        super().__init__(message)
        self.point = point


class FluidForce(nn.Module):
    """F_D = ∫_top P dA [N] for batches of (U [m/s], R [m], H [m]).

    The recompressed basis is held as frozen buffers; ``log_permeability`` is the only
    parameter. Build with ``FluidForce.load(path, permeability=2e-16, viscosity=1e-3)``; ``at`` gives another
    layer on the same basis at another K, sharing this one's tables.
    """

    def __init__(self, basis: Basis, permeability: float, viscosity: float, functions: nn.ModuleDict | None = None):
        super().__init__()
        if not permeability > 0:
            raise ValueError(f"permeability must be > 0 m², got {permeability}")
        if not viscosity > 0:
            raise ValueError(f"viscosity must be > 0 Pa s, got {viscosity}")
        self.coordinates = basis.config.coordinates
        self.basis_hash = basis.config_hash
        self.names = list(basis.force.names)  # the core's order: velocity, permeability, contact_radius, shape
        self.shape = basis.config.shape
        self.viscosity = float(viscosity)
        self.log_permeability = nn.Parameter(torch.tensor(math.log(permeability), dtype=torch.float64))
        self.basis = basis
        if functions is None:  # the basis's tables, unless another layer on it shares its own (``at``)
            functions = nn.ModuleDict(
                {
                    name: LogGridFunctions(basis.grids[name][0], basis.grids[name][1], values)
                    for name, values in zip(self.names, basis.force.functions)
                }
            )
        self.functions = functions
        self.register_buffer("core", basis.force.core)
        if self.coordinates == "scaled" and self.functions["contact_radius"].power_law is None:
            raise ValueError("basis: the contact-radius mode is not a power law; rebuild it")
        laws = [self.functions[name].power_law for name in ("velocity", "permeability", "contact_radius")]
        shape = self.functions[self.shape]
        # The fused path's law: F = prefactor·U·R³/K·c(x), c one-signed; μ is in the prefactor, as every
        # constant factor taken into the fused node is one op fewer in every Jacobian's graph.
        self._separable_prefactor = None
        if [law and law[1] for law in laws] == [1, -1, 3] and shape.rank == 1 and shape.logarithmic:
            coefficient = math.prod(law[0] for law in laws) * self.core.item() * shape.signs.item()
            self._separable_prefactor = self.viscosity * coefficient

    @classmethod
    def load(cls, path: str | Path, permeability: float = 2e-16, viscosity: float = 1e-3) -> FluidForce:
        return cls(Basis.load(path), permeability, viscosity)

    def at(self, permeability: float) -> FluidForce:
        """A fresh layer at K = ``permeability`` [m²] on this one's basis and viscosity. Its tables (splines and
        power laws fitted to the basis: milliseconds, every model a fit builds) are this one's: read-only
        buffers, so one set serves every layer."""
        return FluidForce(self.basis, permeability, self.viscosity, self.functions)

    @property
    def permeability(self) -> torch.Tensor:
        """Current permeability K [m²]."""
        return self.log_permeability.exp()

    def forward(self, velocity: torch.Tensor, contact_radius: torch.Tensor, height: torch.Tensor) -> torch.Tensor:
        return self.evaluate(velocity, contact_radius, height, self.permeability)

    def evaluate(self, velocity, contact_radius, height, permeability) -> torch.Tensor:
        """The force for an explicit permeability [m²]: a scalar, or one per point of the batch."""
        shape = velocity.shape
        if not shape == contact_radius.shape == height.shape:  # torch.broadcast_shapes is Python: ~1 ms a call
            shape = torch.broadcast_shapes(shape, contact_radius.shape, height.shape)
        u, r, h = (t.expand(shape).reshape(-1) for t in (velocity, contact_radius, height))
        self._check_inputs(u, r, h)
        smallest = self.functions["contact_radius"].minimum
        scale = None
        below = r < smallest
        if bool(below.any()):
            safe_r = torch.where(r > 0, r, torch.full_like(r, smallest))
            scale = torch.where(below, (r / smallest) ** 3, torch.ones_like(r))
            h = torch.where(below, h * smallest / safe_r, h)
            r = torch.where(below, torch.full_like(r, smallest), r)
        last = h / r if self.coordinates == "scaled" else h
        last = self._in_range(self.shape, last, clamp_above=self.shape == "aspect_ratio")
        force = self._force(u, r, last, permeability.reshape(-1))  # one K, or one per point
        return (force if scale is None else scale * force).reshape(shape)

    def _force(self, u, r, last, permeability) -> torch.Tensor:
        """F on the grids (R at or above its minimum) [N]."""
        if self._separable_prefactor is not None:
            return _SeparableLaw.apply(u, r, last, permeability, self.functions[self.shape], self._separable_prefactor)[
                0
            ]
        values = {
            "velocity": u,
            "permeability": permeability,
            "contact_radius": self._in_range("contact_radius", r),
            self.shape: last,
        }
        factors = [self.functions[name](values[name]) for name in self.names]
        if self.core.numel() == 1:
            rank_one = factors[0][:, 0] * factors[1][:, 0] * factors[2][:, 0] * factors[3][:, 0]
            return self.viscosity * self.core.reshape(()) * rank_one
        # One dimension at a time, last first: the widest intermediate is (B, r0·r1·r2),
        # where a single einsum over the core would build (B, r1·r2·r3) (GBs per 1e6 points).
        value = factors[3] @ self.core.reshape(-1, self.core.shape[3]).T
        for factor in (factors[2], factors[1], factors[0]):
            value = (value.reshape(value.shape[0], -1, factor.shape[1]) * factor[:, None, :]).sum(-1)
        return self.viscosity * value[:, 0]

    @staticmethod
    def _check_inputs(velocity, contact_radius, height) -> None:
        """``FluidInputError`` at the first point whose velocity is not finite, or whose contact radius or
        height is not a finite non-negative length (before a NaN reaches a grid index)."""
        for name, values, non_negative in (
            ("velocity", velocity, False),
            ("contact radius", contact_radius, True),
            ("height", height, True),
        ):
            good = torch.isfinite(values) & (values >= 0) if non_negative else torch.isfinite(values)
            if not bool(good.all()):
                point = int((~good).nonzero()[0])
                raise FluidInputError(
                    f"FluidForce: {name} {values[point].item():.3g} at point {point} is not a finite"
                    f"{' non-negative' if non_negative else ''} number",
                    point,
                )

    def _in_range(self, name: str, values: torch.Tensor, clamp_above: bool = False) -> torch.Tensor:
        function = self.functions[name]
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
