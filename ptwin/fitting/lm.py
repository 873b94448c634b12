"""Levenberg–Marquardt on torch.func: least squares over chosen parameters of a module.

Jacobians by ``jacfwd`` (tall: many residuals, few parameters), Marquardt scaling
(the damping acts on diag(JᵀJ), so parameters of any unit are treated alike), Nielsen's
gain-ratio damping update, and an optional per-parameter learning rate that scales
each accepted step (a lower rate for K than for a network, as the paper trains).
The state is a plain dict of tensors: a checkpoint resumes it exactly.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch
from torch import nn
from torch.func import jacfwd


class ParameterVector:
    """Named parameters of ``module`` as one flat float64 vector θ, and back."""

    def __init__(self, module: nn.Module, names: Sequence[str]):
        params = dict(module.named_parameters())
        missing = [n for n in names if n not in params]
        if missing:
            raise KeyError(f"no parameter(s) {missing} in the model; it has {sorted(params)}")
        self.module, self.names = module, list(names)
        self.shapes = [params[n].shape for n in names]
        self.sizes = [params[n].numel() for n in names]

    def get(self) -> torch.Tensor:
        params = dict(self.module.named_parameters())
        return torch.cat([params[n].detach().reshape(-1) for n in self.names])

    def as_dict(self, theta: torch.Tensor) -> dict[str, torch.Tensor]:
        return {n: v.reshape(s) for n, v, s in zip(self.names, theta.split(self.sizes), self.shapes)}

    def set(self, theta: torch.Tensor) -> None:
        params = dict(self.module.named_parameters())
        with torch.no_grad():
            for name, value in self.as_dict(theta).items():
                params[name].copy_(value)

    def expand(self, per_name: dict[str, float]) -> torch.Tensor:
        """A per-entry vector from one value per parameter name (default 1)."""
        return torch.cat([torch.full((s,), float(per_name.get(n, 1.0))) for n, s in zip(self.names, self.sizes)]).to(
            torch.float64
        )


@dataclass
class Step:
    iteration: int
    cost: float  # ½‖r‖² after the step
    accepted: bool
    damping: float
    gradient: torch.Tensor  # Jᵀr before the step, per entry of θ


class LevenbergMarquardt:
    """Minimise ½‖residual(θ)‖². ``learning_rate``: one factor per entry of θ (default 1)."""

    def __init__(
        self,
        residual: Callable[[torch.Tensor], torch.Tensor],
        theta: torch.Tensor,
        learning_rate: torch.Tensor | None = None,
        damping: float = 1e-3,
    ):
        self.residual = residual
        self.learning_rate = torch.ones_like(theta) if learning_rate is None else learning_rate.to(theta)
        self.state = {
            "theta": theta.clone(),
            "damping": torch.tensor(float(damping), dtype=torch.float64),
            "nu": torch.tensor(2.0, dtype=torch.float64),
            "iteration": torch.tensor(0),
            "cost": torch.tensor(float("nan"), dtype=torch.float64),
        }

    @property
    def theta(self) -> torch.Tensor:
        return self.state["theta"]

    def linearise(self, theta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(J, r) at θ."""

        def twice(t):
            r = self.residual(t)
            return r, r

        return jacfwd(twice, has_aux=True)(theta)

    def step(self) -> Step:
        s = self.state
        jacobian, r = self.linearise(s["theta"])
        normal = jacobian.T @ jacobian
        gradient = jacobian.T @ r
        cost = 0.5 * (r @ r)
        scale = normal.diagonal().clamp(min=1e-12 * normal.diagonal().max().clamp(min=1e-300))
        delta = -torch.linalg.solve(normal + s["damping"] * torch.diag(scale), gradient) * self.learning_rate
        predicted = -(gradient @ delta + 0.5 * delta @ normal @ delta)
        with torch.no_grad():
            trial = self.residual(s["theta"] + delta)
        new_cost = 0.5 * (trial @ trial)
        gain = (cost - new_cost) / predicted if predicted > 0 else torch.tensor(-1.0)
        accepted = bool(torch.isfinite(new_cost) and gain > 0)
        if accepted:
            s["theta"] = s["theta"] + delta
            s["damping"] = s["damping"] * max(1 / 3, 1 - (2 * gain.item() - 1) ** 3)
            s["nu"] = torch.tensor(2.0, dtype=torch.float64)
            s["cost"] = new_cost.detach()
        else:
            s["damping"] = s["damping"] * s["nu"]
            s["nu"] = s["nu"] * 2
            s["cost"] = cost.detach()
        s["iteration"] = s["iteration"] + 1
        return Step(int(s["iteration"]), s["cost"].item(), accepted, s["damping"].item(), gradient.detach())

    def run(self, iterations: int, tolerance: float = 1e-10, callback: Callable[[Step], None] | None = None):
        """Up to ``iterations`` steps; stops when an accepted step lowers the cost by < ``tolerance`` (relative)."""
        while int(self.state["iteration"]) < iterations:
            before = self.state["cost"].item()
            step = self.step()
            if callback is not None:
                callback(step)
            if step.accepted and before - step.cost <= tolerance * before:
                break
            if step.damping > 1e12:
                break
        return self.theta


def covariance(jacobian: torch.Tensor, residual: torch.Tensor) -> torch.Tensor:
    """σ²(JᵀJ)⁻¹ with σ² = ‖r‖²/(n − p): the parameters' covariance at a least-squares optimum."""
    n, p = jacobian.shape
    variance = (residual @ residual) / max(n - p, 1)
    return variance * torch.linalg.pinv(jacobian.T @ jacobian, hermitian=True)
