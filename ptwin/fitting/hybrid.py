"""Stage 3 (paper §5.3): the hybrid twin — physics with K learnable, plus a small
network that learns the model error.

Cost, with E = F − F_physics and residuals in units of the noise floor σ:
J = ½‖E/σ‖² + ½‖(Y1 − E)/σ‖² + (λ/2)‖Θ‖². K is first converged alone by the
paper's regularised Newton update; then (K, Θ) together by Levenberg–Marquardt with
a learning rate per parameter group.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import nn

from ptwin.fitting.lm import ParameterVector, Traced, evaluated_at
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

    def fit_output(self, samples: Samples, index: torch.Tensor, error: torch.Tensor, regularisation: float) -> None:
        """Set the output layer to the minimiser of ½‖(Y1 − ``error``)/σ‖² + (λ/2)‖its weights and bias‖² on
        ``samples[index]`` (``error`` [N] there, σ the noise floor, λ ``regularisation``), the hidden layers as they
        are: the twin's cost (``HybridResidual``) over the parameters it is linear in, solved in one ridge system.

        LM from the seeded output layer stalled where the output layer alone does better: on the demo at the coarse
        basis, validation RMS at the best λ of the grid 2.4×, 1.10× and 1.38× the noise std at seeds 0, 1 and 2
        (at λ 0.01, seed 0: 5.4×); from this start 1.08×, 1.08× and 1.05×, and 1.17× at the worst λ."""
        *hidden, output = self.layers
        with torch.no_grad():
            h = self._standardised(samples)[index]
            for layer in hidden:
                h = layer(h)
            weight = (self.force_scale / samples.noise_floor[index])[:, None]
            design = torch.cat([h, torch.ones_like(h[:, :1])], 1) * weight
            target = error / samples.noise_floor[index]
            # The ridge system as least squares on the design stacked over √λ·I, by SVD: at λ = 0 with hidden units
            # that act alike (a rank-deficient design) it is the least-norm optimum. Solving the normal equations
            # and falling back where LU said singular depended on rounding: with the BLAS on one thread the solve
            # went through and put the whole weight on one of two equal units (−550 and 0).
            eye = torch.eye(design.shape[1], dtype=design.dtype, device=design.device)
            stacked = torch.cat([design, math.sqrt(regularisation) * eye])
            padded = torch.cat([target, torch.zeros_like(eye[0])])
            solution = torch.linalg.lstsq(stacked, padded[:, None], driver="gelsd").solution[:, 0]
            output.weight.copy_(solution[:-1][None, :])
            output.bias.copy_(solution[-1:])

    def forward(self, samples: Samples) -> torch.Tensor:
        return self._output(self.layers, self._standardised(samples))

    def _standardised(self, samples: Samples) -> torch.Tensor:
        return (self.features(samples) - self.mean) / self.scale

    def _output(self, layers, x: torch.Tensor) -> torch.Tensor:
        return self.force_scale * layers(x).squeeze(-1)

    def jacobian(self, samples: Samples, index: torch.Tensor, values: dict[str, torch.Tensor]):
        """(∂Y1/∂θ (n, p), Y1 (n,)) [N] on ``samples[index]`` with this network's parameters set to ``values``
        ({name: tensor}; θ their entries in that order; the others stay as they are).

        Y1 of a sample depends on that sample alone, so the gradient of ΣY1 with respect to a linear layer's
        output, taken in one reverse pass, holds every sample's own: δ (n, out). That sample's gradients are
        then δ ⊗ the layer's input for the weight and δ for the bias. ``torch.func``'s vmap of grad gives the
        same rows (the tests compare them), but its first call imports torch._dynamo, a second of every run.
        """
        layer_values = {name.removeprefix("layers."): value for name, value in values.items()}
        inputs, outputs = {}, {}  # of each linear layer, by its position
        h = self._standardised(samples)[index].detach()
        with torch.enable_grad():
            for position, layer in enumerate(self.layers):
                if not isinstance(layer, nn.Linear):
                    h = layer(h)
                    continue
                inputs[position] = h.detach()
                weight, bias = (
                    layer_values.get(f"{position}.{p}", getattr(layer, p)).detach() for p in ("weight", "bias")
                )
                h = nn.functional.linear(h, weight, bias)
                outputs[position] = h if outputs else h.requires_grad_(True)  # the graph starts at the first
            output = self.force_scale * h.squeeze(-1)
            deltas = dict(zip(outputs, torch.autograd.grad(output.sum(), list(outputs.values()))))
        gradients = {}
        for position, delta in deltas.items():
            gradients[f"{position}.weight"] = (delta[:, :, None] * inputs[position][:, None, :]).flatten(1)
            gradients[f"{position}.bias"] = delta
        columns = [gradients[name] for name in layer_values]
        return torch.cat(columns, 1) if columns else output.new_zeros(output.numel(), 0), output.detach()


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

    def start_network(self, samples: Samples, index: torch.Tensor, regularisation: float) -> None:
        """The network's output layer at the least-squares optimum of the twin's cost on ``samples[index]`` under
        ``regularisation`` (λ), the physics and the hidden layers as they are (``ErrorNetwork.fit_output``)."""
        with torch.no_grad():
            error = samples.force[index] - self.physics(samples)[index]
        self.network.fit_output(samples, index, error, regularisation)

    def parameter_groups(self) -> dict[str, list[str]]:
        """Names of the parameters per group: the physics (K and any terms) and the network."""
        names = [n for n, _ in self.named_parameters()]
        return {
            "physics": [n for n in names if n.startswith("physics.")],
            "network": [n for n in names if n.startswith("network.")],
        }


def hybrid_residual(twin: HybridTwin, samples: Samples, index: torch.Tensor, regularisation: float, names):
    """(ParameterVector over ``names``, ``HybridResidual``: θ ↦ [E/σ, (Y1 − E)/σ, √λ Θ], J = ½‖·‖²)."""
    vector = ParameterVector(twin, names)
    return vector, HybridResidual(twin, samples, index, regularisation, vector)


class HybridResidual:
    """θ ↦ [E/σ, (Y1 − E)/σ, √λ Θ] on ``samples[index]``, θ the entries of ``vector``; ``trace(θ)`` → it evaluated
    there (``TracedHybrid``), ``linearise(θ)`` → (J, r).

    The physics model depends on its own parameters only and the network on its own, so each is
    differentiated apart — the physics by reverse mode (``Traced``) over its few parameters, the network by
    per-sample gradients (``ErrorNetwork.jacobian``) — and J follows by the chain rule through the residual's
    assembly (``_assembled_jacobian``). (jacfwd over all of θ pushed the network's ~25 tangents through every sample:
    most of a hybrid step.)
    """

    def __init__(self, twin: HybridTwin, samples: Samples, index: torch.Tensor, regularisation: float, vector):
        self.twin, self.samples, self.index, self.regularisation = twin, samples, index, regularisation
        self.vector = vector
        self.force, self.noise = samples.force[index], samples.noise_floor[index]
        owners = [name for name, size in zip(vector.names, vector.sizes) for _ in range(size)]  # per entry of θ
        self.columns = {
            part: torch.tensor(
                [i for i, name in enumerate(owners) if name.startswith(f"{part}.")],
                dtype=torch.long,
                device=self.force.device,
            )
            for part in ("physics", "network")
        }

    def _own(self, part: str, theta: torch.Tensor) -> dict[str, torch.Tensor]:
        """θ's values of the physics model's or the network's parameters, by their names within it."""
        return {n[len(part) + 1 :]: v for n, v in self.vector.as_dict(theta).items() if n.startswith(f"{part}.")}

    def _prediction(self, part: str, theta: torch.Tensor) -> torch.Tensor:
        """The physics force or the network's correction on the samples [N] at θ."""
        return evaluated_at(getattr(self.twin, part), self._own(part, theta), self.samples)[self.index]

    def _assemble(self, physics: torch.Tensor, correction: torch.Tensor, theta: torch.Tensor) -> torch.Tensor:
        error = (self.force - physics) / self.noise
        mismatch = correction / self.noise - error
        return torch.cat([error, mismatch, self.regularisation**0.5 * theta[self.columns["network"]]])

    def __call__(self, theta: torch.Tensor) -> torch.Tensor:
        return self._assemble(self._prediction("physics", theta), self._prediction("network", theta), theta)

    def trace(self, theta: torch.Tensor) -> TracedHybrid:
        """The residual evaluated at θ, the physics with its graph (LM's trial, then its Jacobian if accepted)."""
        return TracedHybrid(self, theta)

    def linearise(self, theta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(J, r) at θ."""
        return self.trace(theta).jacobian_and_value()

    def _assembled_jacobian(self, jacobians: dict[str, torch.Tensor], theta: torch.Tensor) -> torch.Tensor:
        """∂/∂θ of ``_assemble`` from each model's own Jacobian: the error −∂F/σ, the mismatch (∂Y1 + ∂F)/σ, the
        penalty √λ on the network's entries. Written out rather than pushed through ``_assemble`` by jacfwd
        (which spent half a hybrid step on a map that is linear); the same numbers, to the bit."""
        physics, network = self.columns["physics"], self.columns["network"]
        samples = self.force.numel()
        jacobian = theta.new_zeros(2 * samples + network.numel(), theta.numel())
        jacobian[:samples, physics] = -jacobians["physics"] / self.noise[:, None]
        jacobian[samples : 2 * samples, physics] = jacobians["physics"] / self.noise[:, None]
        jacobian[samples : 2 * samples, network] = jacobians["network"] / self.noise[:, None]
        jacobian[2 * samples + torch.arange(network.numel(), device=network.device), network] = self.regularisation**0.5
        return jacobian


class TracedHybrid:
    """``HybridResidual`` at θ: its value now; (J, r) later from the physics' kept graph (``Traced``, over its
    own few parameters) and the network's per-sample gradients (``ErrorNetwork.jacobian``)."""

    def __init__(self, residual: HybridResidual, theta: torch.Tensor):
        self.residual, self.theta = residual, theta
        physics = residual.columns["physics"]
        self.physics = None
        if physics.numel():
            self.physics = Traced(
                lambda entries: residual._prediction("physics", theta.index_copy(0, physics, entries)), theta[physics]
            )
            force = self.physics.value
        else:
            with torch.no_grad():
                force = residual._prediction("physics", theta)
        self.force = force
        with torch.no_grad():
            self.value = residual._assemble(force, residual._prediction("network", theta), theta)

    def jacobian_and_value(self) -> tuple[torch.Tensor, torch.Tensor]:
        residual, theta = self.residual, self.theta
        if self.physics is not None:
            physics_jacobian, _ = self.physics.jacobian_and_value()
        else:
            physics_jacobian = self.force.new_zeros(self.force.numel(), 0)
        network = residual._own("network", theta)
        network_jacobian, correction = residual.twin.network.jacobian(residual.samples, residual.index, network)
        jacobian = residual._assembled_jacobian({"physics": physics_jacobian, "network": network_jacobian}, theta)
        return jacobian, residual._assemble(self.force, correction, theta)


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
    linearise = residual.linearise
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
