"""Training the hybrid twin: one LM run per λ of the grid, λ chosen on the validation set.

Every run starts from the same state (K from the regularised Newton, the network's
seeded hidden layer), its output layer at the least-squares optimum of that λ's cost
(``ErrorNetwork.fit_output``), so runs are independent and a resumed run repeats exactly
what an uninterrupted one does. ``save`` receives a plain-dict state every
``checkpoint_every`` steps and after each λ; ``resume`` takes such a state back (one
saved after the last λ resumes to the finished twin without training).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import torch

from ptwin.checks import refuse_outside
from ptwin.fitting.hybrid import HybridTwin, hybrid_residual, newton_permeability
from ptwin.fitting.lm import LevenbergMarquardt, ParameterVector, Step
from ptwin.physics.samples import Samples


@dataclass
class HybridSettings:
    regularisations: list[float] = field(default_factory=lambda: [1.0e-4, 1.0e-2, 1.0])  # the λ grid
    iterations: int = 60
    damping: float = 1.0e-3
    tolerance: float = 1.0e-10
    learning_rate: dict[str, float] = field(default_factory=lambda: {"physics": 0.5, "network": 1.0})
    newton_c1: float = 1.0
    newton_iterations: int = 30
    checkpoint_every: int = 10

    def __post_init__(self):
        grid, rates = self.regularisations, self.learning_rate
        rules = [
            (
                "regularisations",
                bool(grid) and all(0.0 <= v < math.inf for v in grid),
                "one λ ≥ 0 or more, e.g. [1.0e-2]",
            ),
            ("iterations", self.iterations >= 0, "0 or more LM steps a λ, e.g. 60"),
            ("damping", 0.0 < self.damping < math.inf, "LM's first damping, positive, e.g. 1.0e-3"),
            ("tolerance", 0.0 <= self.tolerance < 1.0, "a relative fall of the cost, from 0 to below 1, e.g. 1.0e-10"),
            (
                "learning_rate",
                set(rates) == {"physics", "network"} and all(0.0 < r < math.inf for r in rates.values()),
                "a positive rate for physics and for network, e.g. {physics: 0.5, network: 1.0}",
            ),
            ("newton_c1", 0.0 <= self.newton_c1 < math.inf, "0 or more, e.g. 1.0"),
            ("newton_iterations", self.newton_iterations >= 0, "0 or more Newton steps, e.g. 30"),
            ("checkpoint_every", self.checkpoint_every >= 1, "1 or more LM steps, e.g. 10"),
        ]
        refuse_outside(self, rules, "optim.hybrid.{}".format)


@dataclass
class HybridOutcome:
    twin: HybridTwin
    regularisation: float  # the λ chosen
    val_rmse: list[float]  # [N], one per λ
    iterations: list[int]
    newton_iterations: int


def rmse_of(twin: HybridTwin, samples: Samples, index: torch.Tensor) -> float:
    with torch.no_grad():
        return (twin.predict(samples)[index] - samples.force[index]).square().mean().sqrt().item()


def train_hybrid(
    make_twin: Callable[[], HybridTwin],
    samples: Samples,
    train: torch.Tensor,
    val: torch.Tensor,
    settings: HybridSettings,
    on_step: Callable[[int, float, Step, HybridTwin, LevenbergMarquardt], None] | None = None,
    save: Callable[[dict], None] | None = None,
    resume: dict | None = None,
) -> HybridOutcome:
    """Train one twin per λ; return the one with the lowest validation RMSE."""
    progress = resume or {"lambda_index": 0, "val_rmse": [], "iterations": [], "best": None, "run": None}
    twin = make_twin()
    newton = newton_permeability(
        twin, samples, train, settings.regularisations[0], settings.newton_c1, settings.newton_iterations
    )
    start = {n: p.detach().clone() for n, p in twin.named_parameters()}
    groups = twin.parameter_groups()
    names = groups["physics"] + groups["network"]
    vector = ParameterVector(twin, names)
    for index in range(progress["lambda_index"], len(settings.regularisations)):
        regularisation = settings.regularisations[index]
        twin.load_state_dict(start, strict=False)
        twin.start_network(samples, train, regularisation)
        _, residual = hybrid_residual(twin, samples, train, regularisation, names)
        rates = {n: settings.learning_rate[g] for g, members in groups.items() for n in members}
        solver = LevenbergMarquardt(residual, vector.get(), vector.expand(rates), settings.damping, residual.trace)
        if progress["run"] is not None:
            solver.state = {k: v.clone() for k, v in progress["run"].items()}
        progress["lambda_index"] = index

        def callback(step: Step, regularisation=regularisation, solver=solver):
            vector.set(solver.theta)
            if on_step is not None:
                on_step(progress["lambda_index"], regularisation, step, twin, solver)
            if save is not None and step.iteration % settings.checkpoint_every == 0:
                save({**progress, "run": solver.state})

        solver.run(settings.iterations, settings.tolerance, callback)
        vector.set(solver.theta)
        progress["val_rmse"].append(rmse_of(twin, samples, val))
        progress["iterations"].append(int(solver.state["iteration"]))
        if progress["best"] is None or progress["val_rmse"][-1] < min(progress["val_rmse"][:-1]):
            progress["best"] = {"index": index, "theta": solver.theta.clone()}
        progress["lambda_index"], progress["run"] = index + 1, None
        if save is not None:
            save(progress)
    best = progress["best"]
    vector.set(best["theta"])
    return HybridOutcome(
        twin=twin,
        regularisation=settings.regularisations[best["index"]],
        val_rmse=progress["val_rmse"],
        iterations=progress["iterations"],
        newton_iterations=newton,
    )
