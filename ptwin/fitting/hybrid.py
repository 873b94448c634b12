"""Stage 3 (paper §5.3): the hybrid twin — physics with K learnable, plus a small
network that learns the model error.

Cost, with E = F − F_physics and residuals in units of the noise floor σ:
J = ½‖E/σ‖² + ½‖(Y1 − E)/σ‖² + (λ/2)‖Θ‖². K is first converged alone by the
paper's regularised Newton update; then (K, Θ) together by Levenberg–Marquardt with
a learning rate per parameter group.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn
from torch.func import functional_call

from ptwin.fitting.lm import LevenbergMarquardt, ParameterVector
from ptwin.physics.model import PERMEABILITY, ForceModel
from ptwin.physics.samples import Samples

ACTIVATIONS = {"sigmoid": nn.Sigmoid, "tanh": nn.Tanh, "relu": nn.ReLU}
INPUTS = {
    "depth": lambda s: s.depth,
    "base_speed": lambda s: s.nominal_speed.log10(),  # the curve's approach speed (a hold's base is at 0)
    "velocity": lambda s: s.velocity,
    "time": lambda s: s.time,
}


def check_network(inputs: Sequence[str], activation: str) -> None:
    """ValueError naming the fix, unless ``inputs`` are names of ``INPUTS`` and ``activation`` of ``ACTIVATIONS``."""
    unknown = set(inputs) - set(INPUTS)
    if unknown or activation not in ACTIVATIONS:
        raise ValueError(
            f"model: inputs must be among {sorted(INPUTS)} and activation among {sorted(ACTIVATIONS)}; "
            f"got inputs {list(inputs)}, activation {activation!r}"
        )


class ErrorNetwork(nn.Module):
    """Y1 [N]: an MLP of standardised inputs (names of ``INPUTS``), output in units of ``force_scale``.

    The default — inputs (depth, base speed), 6 sigmoid neurons, linear output — has the
    paper's 25 parameters.
    """

    def __init__(
        self,
        inputs: Sequence[str],
        hidden: int,
        activation: str,
        samples: Samples,
        index: torch.Tensor,
        force_scale: float,
        generator: torch.Generator,
    ):
        super().__init__()
        check_network(inputs, activation)
        self.inputs = list(inputs)
        features = self.features(samples)[index]
        self.register_buffer("mean", features.mean(0))
        self.register_buffer("scale", features.std(0).clamp(min=1e-300))
        self.force_scale = force_scale
        self.layers = nn.Sequential(
            nn.Linear(len(inputs), hidden, dtype=torch.float64),
            ACTIVATIONS[activation](),
            nn.Linear(hidden, 1, dtype=torch.float64),
        )
        with torch.no_grad():
            for p in self.layers.parameters():
                p.copy_(torch.randn(p.shape, generator=generator, dtype=torch.float64) / p.shape[-1] ** 0.5)

    def features(self, samples: Samples) -> torch.Tensor:
        return torch.stack([INPUTS[name](samples) for name in self.inputs], dim=1)

    def forward(self, samples: Samples) -> torch.Tensor:
        x = (self.features(samples) - self.mean) / self.scale
        return self.force_scale * self.layers(x).squeeze(1)


class HybridTwin(nn.Module):
    """(F_physics, Y1) [N] per sample; the twin predicts their sum."""

    def __init__(self, physics: ForceModel, network: ErrorNetwork):
        super().__init__()
        self.physics, self.network = physics, network

    def forward(self, samples: Samples) -> tuple[torch.Tensor, torch.Tensor]:
        return self.physics(samples), self.network(samples)

    def predict(self, samples: Samples) -> torch.Tensor:
        physics, correction = self(samples)
        return physics + correction

    def parameter_groups(self) -> dict[str, list[str]]:
        """Names of the parameters per group: the physics (K and any terms) and the network."""
        names = [n for n, _ in self.named_parameters()]
        return {
            "physics": [n for n in names if n.startswith("physics.")],
            "network": [n for n in names if n.startswith("network.")],
        }


def hybrid_residual(twin: HybridTwin, samples: Samples, index: torch.Tensor, regularisation: float, names):
    """θ ↦ [E/σ, (Y1 − E)/σ, √λ Θ] for the parameters ``names`` (J = ½‖·‖²)."""
    vector = ParameterVector(twin, names)
    network = [n for n in names if n.startswith("network.")]
    force, noise = samples.force[index], samples.noise_floor[index]

    def residual(theta):
        values = vector.as_dict(theta)
        physics, correction = functional_call(twin, values, (samples,))
        error = (force - physics[index]) / noise
        mismatch = correction[index] / noise - error
        weights = torch.cat([values[n].reshape(-1) for n in network]) if network else theta[:0]
        return torch.cat([error, mismatch, regularisation**0.5 * weights])

    return vector, residual


def newton_permeability(
    twin: HybridTwin,
    samples: Samples,
    index: torch.Tensor,
    regularisation: float,
    c1: float = 1.0,
    iterations: int = 30,
    tolerance: float = 1e-10,
) -> int:
    """Converge K alone: log K ← log K − J*/(∂J*/∂log K + c1·|J*|), J* = ∂J/∂log K.

    ∂J*/∂log K is the Gauss–Newton curvature; c1 damps the step where the gradient is
    large (far from the optimum). Returns the iterations used.
    """
    name = f"physics.{PERMEABILITY}"
    vector, residual = hybrid_residual(twin, samples, index, regularisation, [name])
    linearise = LevenbergMarquardt(residual, vector.get()).linearise
    log_k = vector.get()
    iteration = 0
    while iteration < iterations:
        iteration += 1
        jacobian, r = linearise(log_k)
        gradient = jacobian[:, 0] @ r
        curvature = jacobian[:, 0] @ jacobian[:, 0]
        step = gradient / (curvature + c1 * gradient.abs())
        log_k = log_k - step
        if step.abs().item() < tolerance:
            break
    vector.set(log_k)
    return iteration
