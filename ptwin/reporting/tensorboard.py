"""TensorBoard events and a progress bar for the hybrid twin's training (tags as in style.md:
``loss/train``, ``loss/val``, ``param/permeability``, ``lambda``, ``damping``,
``grad_norm/<group>``, ``lr/<group>``, the figures, and the run's hparams)."""

from __future__ import annotations

from pathlib import Path

import torch
from PIL import Image
from tensorboard.compat.proto.summary_pb2 import Summary
from torch.utils.tensorboard import SummaryWriter
from tqdm import tqdm

from ptwin.fitting.hybrid import HybridTwin
from ptwin.fitting.hybrid_training import HybridSettings, rmse_of
from ptwin.fitting.lm import LevenbergMarquardt, Step
from ptwin.physics.samples import Samples

VALIDATION_EVERY = 5  # LM steps between points of the validation loss curve


class TrainingLog:
    """Logs each LM step of ``train_hybrid`` (pass ``on_step``) to an event file of its own in ``folder``; losses in
    units of ``noise`` [N]². ``bar``: a progress bar on a terminal (off where other lines are said meanwhile)."""

    def __init__(
        self,
        folder: Path,
        samples: Samples,
        train: torch.Tensor,
        val: torch.Tensor,
        noise: float,
        settings: HybridSettings,
        bar: bool = True,
    ):
        self.writer = SummaryWriter(folder)
        self.samples, self.val, self.noise, self.settings = samples, val, noise, settings
        self.train_size = train.numel()
        total = len(settings.regularisations) * settings.iterations
        self.bar = tqdm(total=total, desc="hybrid LM", unit="step", disable=None if bar else True)  # None: a terminal

    def on_step(
        self, lambda_index: int, regularisation: float, step: Step, twin: HybridTwin, solver: LevenbergMarquardt
    ) -> None:
        global_step = lambda_index * self.settings.iterations + step.iteration
        self.bar.update(global_step - self.bar.n)
        self.bar.set_postfix(λ=f"{regularisation:g}", cost=f"{step.cost:.4g}")
        write = self.writer.add_scalar
        groups = twin.parameter_groups()
        names = groups["physics"] + groups["network"]
        write("loss/train", 2 * step.cost / self.train_size, global_step)
        if step.iteration % VALIDATION_EVERY == 0:  # a prediction of every sample: 8% of the demo's run each step
            write("loss/val", (rmse_of(twin, self.samples, self.val) / self.noise) ** 2, global_step)
        write("param/permeability", twin.physics.fluid.permeability.item(), global_step)
        write("lambda", regularisation, global_step)
        write("damping", step.damping, global_step)
        sizes = [p.numel() for n, p in twin.named_parameters() if n in names]
        for group, members in groups.items():
            gradient = torch.cat([g for g, n in zip(step.gradient.split(sizes), names) if n in members])
            write(f"grad_norm/{group}", gradient.norm().item(), global_step)
            write(f"lr/{group}", self.settings.learning_rate[group], global_step)

    def end_training(self) -> None:
        self.bar.close()
        self.writer.close()


def write_summary(folder: Path, images: dict[str, Path], hparams: dict, metrics: dict) -> None:
    """The run's figures (their saved PNG files as they are: decoding and encoding them again took 0.27 s of the
    demo's run) and its hyperparameters with their metrics, in an event file of their own in ``folder``."""
    writer = SummaryWriter(folder)
    for name, path in images.items():
        with Image.open(path) as image:  # reads the header only
            (width, height), bands = image.size, len(image.getbands())
        png = Summary.Image(height=height, width=width, colorspace=bands, encoded_image_string=path.read_bytes())
        writer.file_writer.add_summary(Summary(value=[Summary.Value(tag=name, image=png)]))
    writer.add_hparams(hparams, metrics, run_name=".")
    writer.close()
