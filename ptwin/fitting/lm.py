"""Levenberg–Marquardt: least squares over chosen parameters of a module.

Jacobians by reverse mode (``Traced``), Marquardt scaling
(the damping acts on diag(JᵀJ), so parameters of any unit are treated alike), Nielsen's
gain-ratio damping update, an optional per-parameter learning rate that scales
each accepted step (a lower rate for K than for a network, as the paper trains), and an
optional per-parameter step limit that shortens a longer step along its direction, and entries whose long
steps are read in their reciprocal (an entry θ fitted in log whose residual is linear in e^(−θ), as log K's Darcy
force is in 1/K).
The state is a plain dict of tensors: a checkpoint resumes it exactly.

A trial step the model cannot evaluate (a parameter outside the model's domain: a
depth beyond the sample, a grid the fluid layer refuses) is a rejected step, like one
that raises the cost; after a rejection θ has not moved, so the Jacobian is reused, and after
an acceptance it comes from the trial's own evaluation (``Traced``): one evaluation a step, and
none after the run for the Jacobian at its end (``linearised``, the fit's covariance).
Only a start the model cannot evaluate, or a Jacobian that is not finite, ends the fit
(``FitError``, with the reason in words).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch
from torch import nn
from torch.func import functional_call

from ptwin.checks import first_line


class Traced:
    """f evaluated at x with its graph kept: the value now, the Jacobian there later without evaluating f again
    (LM traces each trial step and differentiates the accepted ones).

    The Jacobian by reverse mode: the pullback u ↦ Jᵀu once with a graph of its own (the gradient of u·f), then
    each column Jeᵢ as the gradient of the pullback's i-th entry, which is linear in u. The fits' Jacobians are
    tall (hundreds of residuals, 1–3 parameters), forward mode's case, but torch's forward AD (``jacfwd``) gives
    operands without a tangent zero tensors that take a slow path: on the bench map's spots these p + 2 plain
    passes cost 9.5 ms a Jacobian against ``jacfwd``'s 11.5 ms.

    Gradients of scalars, never ``grad_outputs``: torch checks a grad_output's shape with its symbolic-shapes
    module, whose first use imports sympy (0.4 s of every run); the scalars' two extra ops cost about 45 µs a
    Jacobian.
    """

    def __init__(self, function: Callable[[torch.Tensor], torch.Tensor], x: torch.Tensor):
        self._leaf = x.detach().requires_grad_(True)
        with torch.enable_grad():
            self._value = function(self._leaf)

    @property
    def value(self) -> torch.Tensor:
        return self._value.detach()

    def jacobian_and_value(self) -> tuple[torch.Tensor, torch.Tensor]:
        x, value = self._leaf, self._value
        columns = torch.zeros(value.numel(), x.numel(), dtype=value.dtype, device=value.device)
        if value.requires_grad:
            with torch.enable_grad():
                cotangent = torch.zeros_like(value, requires_grad=True)
                product = torch.dot(value.reshape(-1), cotangent.reshape(-1))
                (pullback,) = torch.autograd.grad(product, x, create_graph=True, materialize_grads=True)
                if pullback.requires_grad:
                    for i, entry in enumerate(pullback.reshape(-1)):
                        (column,) = torch.autograd.grad(entry, cotangent, retain_graph=True, materialize_grads=True)
                        columns[:, i] = column.reshape(-1)
        return columns.reshape(*value.shape, *x.shape), value.detach()


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

    def entry(self, name: str) -> int:
        """Where parameter ``name``'s first value sits in θ."""
        return sum(self.sizes[: self.names.index(name)])

    def as_dict(self, theta: torch.Tensor) -> dict[str, torch.Tensor]:
        return {n: v.reshape(s) for n, v, s in zip(self.names, theta.split(self.sizes), self.shapes)}

    def set(self, theta: torch.Tensor) -> None:
        params = dict(self.module.named_parameters())
        with torch.no_grad():
            for name, value in self.as_dict(theta).items():
                params[name].copy_(value)

    def expand(self, per_name: dict[str, float], default: float = 1.0) -> torch.Tensor:
        """A per-entry vector from one value per parameter name (``default`` for the names not given)."""
        device = self.get().device
        values = [
            torch.full((s,), float(per_name.get(n, default)), dtype=torch.float64, device=device)
            for n, s in zip(self.names, self.sizes)
        ]
        return torch.cat(values)


def evaluated_at(module: nn.Module, values: dict[str, torch.Tensor], *args):
    """``module(*args)`` with ``values`` ({name: tensor}) in place of those parameters (``functional_call``). No
    module ptwin fits ties one parameter to another, so ties are not looked for: mapping them at every evaluation
    was 2% of a bench-map spot's time."""
    return functional_call(module, values, args, tie_weights=False)


class FitError(RuntimeError):
    """A least-squares fit that cannot go on; the message says why, in words."""


@dataclass
class Step:
    iteration: int
    cost: float  # ½‖r‖² after the step
    accepted: bool
    damping: float
    gradient: torch.Tensor  # Jᵀr before the step, per entry of θ
    predicted: float | None  # the decrease of ½‖r‖² the linearised model promised (None: no step solved)


class LevenbergMarquardt:
    """Minimise ½‖residual(θ)‖². ``learning_rate``: one factor per entry of θ (default 1); ``trace``: θ ↦ the
    residual evaluated there, ``.value`` now and ``.jacobian_and_value()`` → (J, r) later, where the residual
    knows a cheaper route than differentiating all of θ at once (default: ``Traced``); ``decrease``: the most
    an accepted step lowers the damping by (Nielsen's 1/3); ``step_limit``: the most one step may move each entry
    of θ (default: no limit); a longer step is shortened along its direction, so it still promises a decrease.
    Where a residual is exponential in an entry (a force ∝ 1/K in log K) its linearisation promises far more
    than a step of many e-folds gives, and LM would learn that by rejected steps while the damping grows.
    ``reciprocal``: the entries θ whose residual is linear in u = e^(−θ) (a mask; each needs a finite step limit).
    Where θ's linearisation asks to lower θ by more than its limit, the step solved, δ, is read in u, where the
    linearisation is exact (u moves by −δ·u), and θ moves by −ln(1 − δ) (``_moved``); the damped system and the
    promised decrease are the step's own. Within the limit the two agree to first order and θ moves by δ, as
    every other entry does. From the fluid-off start (F_D ∝ 1/K at K 1e-9 m²) log K's steps went to the limit
    while the force stayed too small, and the one after them asked for δ −5 where −1.8 was needed: it went to the
    limit again, overshot, and was rejected while the damping grew (six times on the bench map's spots)."""

    def __init__(
        self,
        residual: Callable[[torch.Tensor], torch.Tensor],
        theta: torch.Tensor,
        learning_rate: torch.Tensor | None = None,
        damping: float = 1e-3,
        trace: Callable[[torch.Tensor], Traced] | None = None,
        decrease: float = 1 / 3,
        step_limit: torch.Tensor | None = None,
        reciprocal: torch.Tensor | None = None,
    ):
        self.residual = residual
        self.decrease = decrease
        self.trace = trace if trace is not None else (lambda theta: Traced(residual, theta))
        self.learning_rate = torch.ones_like(theta) if learning_rate is None else learning_rate.to(theta)
        self.step_limit = torch.full_like(theta, math.inf) if step_limit is None else step_limit.to(theta)
        none = torch.zeros_like(theta, dtype=torch.bool)
        self.reciprocal = none if reciprocal is None else reciprocal.to(device=theta.device, dtype=torch.bool)
        if not torch.isfinite(self.step_limit[self.reciprocal]).all():
            raise ValueError("an entry stepped in its reciprocal needs a finite step_limit (e.g. math.log(100))")
        self.state = {
            "theta": theta.clone(),
            "damping": torch.tensor(float(damping), dtype=torch.float64),
            "nu": torch.tensor(2.0, dtype=torch.float64),
            "iteration": torch.tensor(0),
            "cost": torch.tensor(float("nan"), dtype=torch.float64),
        }
        # What is known of the residual at the current θ; a solver fits one model (change the model: a new solver).
        self._linear = None  # (J, r), kept across rejected steps
        self._traced = None  # the last accepted trial with its graph: J without evaluating f again

    @property
    def theta(self) -> torch.Tensor:
        return self.state["theta"]

    def linearise(self, theta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(J, r) at θ."""
        return self.trace(theta).jacobian_and_value()

    def checked_linearise(self, theta: torch.Tensor, traced: Traced | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """(J, r) at θ (from ``traced``, f's evaluation there, where given), or ``FitError`` saying why the model
        cannot be linearised there."""
        try:
            jacobian, r = self.linearise(theta) if traced is None else traced.jacobian_and_value()
        except (ValueError, RuntimeError) as error:  # e.g. the fluid layer refusing a point off its grid
            raise FitError(f"the model cannot be evaluated ({first_line(error)})") from None
        if not (torch.isfinite(jacobian).all() and torch.isfinite(r).all()):
            raise FitError("the model or its derivatives are not finite at these parameters")
        return jacobian, r

    def linearised(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(J, r) at the current θ, as ``checked_linearise``: what the last step left (a rejected step's linearisation,
        an accepted trial's graph) where there is one, else evaluated. A fit's covariance at the end of its run cost
        a forward pass and a Jacobian more (1–2% of a bench-map spot's wall time, 6% under cProfile)."""
        if self._linear is None:
            self._linear = self.checked_linearise(self.theta, self._traced)
            self._traced = None
        return self._linear

    def _trial(self, theta: torch.Tensor) -> tuple[torch.Tensor, Traced | None]:
        """(½‖r(θ)‖², the residual traced there); the cost is infinite where the model cannot be evaluated."""
        try:
            traced = self.trace(theta)
        except (ValueError, RuntimeError):
            return torch.tensor(float("inf"), dtype=torch.float64), None
        return 0.5 * (traced.value @ traced.value), traced

    def step(self) -> Step:
        s = self.state
        jacobian, r = self.linearised()
        normal = jacobian.T @ jacobian
        gradient = jacobian.T @ r
        cost = 0.5 * (r @ r)
        scale = normal.diagonal().clamp(min=1e-12 * normal.diagonal().max().clamp(min=1e-300))
        solved = True
        try:
            delta = -torch.linalg.solve(normal + s["damping"] * torch.diag(scale), gradient) * self.learning_rate
        except RuntimeError:  # singular even with damping: a larger damping next time
            delta, solved = torch.zeros_like(gradient), False
        inverted = self.reciprocal & (delta < -self.step_limit)  # θ's linearisation asks to lower θ past its limit
        delta = delta * self._within_limits(delta, inverted)
        predicted = -(gradient @ delta + 0.5 * delta @ normal @ delta)
        candidate = s["theta"] + self._moved(delta, inverted)
        new_cost, traced = self._trial(candidate)
        gain = (cost - new_cost) / predicted if predicted > 0 else torch.tensor(-1.0)
        accepted = bool(torch.isfinite(new_cost) and gain > 0)
        if accepted:
            self._linear, self._traced = None, traced
            s["theta"] = candidate
            s["damping"] = s["damping"] * max(self.decrease, 1 - (2 * gain.item() - 1) ** 3)
            s["nu"] = torch.tensor(2.0, dtype=torch.float64)
            s["cost"] = new_cost.detach()
        else:
            s["damping"] = s["damping"] * s["nu"]
            s["nu"] = s["nu"] * 2
            s["cost"] = cost.detach()
        s["iteration"] = s["iteration"] + 1
        return Step(
            int(s["iteration"]),
            s["cost"].item(),
            accepted,
            s["damping"].item(),
            gradient.detach(),
            float(predicted) if solved else None,
        )

    def _within_limits(self, delta: torch.Tensor, inverted: torch.Tensor) -> float:
        """The largest fraction ≤ 1 of the solved step ``delta`` whose moves (``_moved``) stay within the step limits
        L: an ``inverted`` entry (δ < 0) moves −ln(1 − δ), within L where δ ≥ −(e^L − 1)."""
        if not delta.numel():
            return 1.0
        room = torch.where(inverted, torch.expm1(self.step_limit), self.step_limit) / delta.abs()
        return min(1.0, float(room.min()))

    @staticmethod
    def _moved(delta: torch.Tensor, inverted: torch.Tensor) -> torch.Tensor:
        """How θ moves for the solved step ``delta``: δ, or −ln(1 − δ) for an ``inverted`` entry (u = e^(−θ) moves
        by −δ·u)."""
        return torch.where(inverted, -torch.log1p(-delta.where(inverted, torch.zeros_like(delta))), delta)

    def run(
        self,
        iterations: int,
        tolerance: float = 1e-10,
        callback: Callable[[Step], None] | None = None,
        settled: float = 0.0,
    ):
        """Up to ``iterations`` steps; stops when an accepted step lowers the cost by < ``tolerance`` (relative)
        or by < ``settled`` (absolute: a gain that means nothing in the cost's own units), or when a rejected
        step promised no more than that: a larger damping only shortens the step and its promise, so the
        steps that would follow end where this one leaves θ, at a cost of one evaluation each (a power law
        at the edge of its range tried eleven of them). Where the normal equations could not be solved there
        was no step: a larger damping is tried. ``settled`` after the run: whether one of these ended it, not the
        ``iterations`` cap."""
        self.settled = False
        while int(self.state["iteration"]) < iterations:
            before = self.state["cost"].item()
            step = self.step()
            if callback is not None:
                callback(step)
            promised = step.predicted is not None and not step.accepted
            self.settled = (
                (step.accepted and before - step.cost <= max(tolerance * before, settled))
                or (promised and step.predicted <= max(tolerance * step.cost, settled))
                or step.damping > 1e12
            )
            if self.settled:
                break
        return self.theta


def covariance(jacobian: torch.Tensor, residual: torch.Tensor, rcond: float = 1e-12) -> torch.Tensor:
    """σ²(JᵀJ)⁻¹ with σ² = ‖r‖²/(n − p): the parameters' covariance at a least-squares optimum.

    Directions the data do not fix (eigenvalues of the Marquardt-scaled JᵀJ below ``rcond``
    of the largest) are not identified: every parameter taking part in one gets an infinite
    variance (and NaN covariances), never the zero a pseudo-inverse would give it.

    The scaling divides J's columns by their norms before JᵀJ is formed: a parameter that barely acts (a pore
    term's K in its K → 0 limit, a column of norm 1e-156 on a real creep) would put a denormal on JᵀJ's diagonal,
    whose reciprocal overflows and fed an infinite matrix to the eigensolver, which failed. Its variance is what
    the arithmetic gives, infinite where it overflows.
    """
    n, p = jacobian.shape
    variance = (residual @ residual) / max(n - p, 1)
    unknown = torch.full((p, p), float("nan"), dtype=jacobian.dtype, device=jacobian.device)
    if not torch.isfinite(jacobian).all() or not torch.isfinite(variance):
        return unknown
    scale = torch.linalg.vector_norm(jacobian, dim=0)
    live = scale > torch.finfo(scale.dtype).tiny  # a norm whose reciprocal is finite
    units = jacobian / scale.where(live, torch.ones_like(scale)) * live
    scaled = units.T @ units + torch.diag((~live).to(jacobian.dtype))
    eigenvalues, vectors = torch.linalg.eigh(0.5 * (scaled + scaled.T))
    kept = eigenvalues > rcond * eigenvalues.max()
    inverse = (vectors[:, kept] / eigenvalues[kept]) @ vectors[:, kept].T
    inverse_scale = torch.where(live, 1.0 / scale.where(live, torch.ones_like(scale)), torch.zeros_like(scale))
    # one factor at a time: a product of the two reciprocals alone can overflow where the covariance is 0
    result = variance * (inverse * inverse_scale[:, None]) * inverse_scale[None, :]
    unidentified = (vectors[:, ~kept].abs() > 1e-6).any(dim=1) | ~live
    result[unidentified, :] = float("nan")
    result[:, unidentified] = float("nan")
    result[unidentified, unidentified] = float("inf")
    return result
