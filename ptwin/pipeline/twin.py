"""Stage 3 (paper §5.3): the hybrid twin, K learnable next to an MLP of the model error,
trained by LM over the λ grid with checkpoints (``ckpt_path`` resumes)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

from ptwin.fitting import checkpoint
from ptwin.fitting.hybrid_training import HybridOutcome, train_hybrid
from ptwin.pipeline.prepare import Prepared
from ptwin.pipeline.settings import Settings


def train_twin(
    prepared: Prepared,
    permeability: float,
    noise: float,
    settings: Settings,
    output_dir: Path,
    on_step: Callable[..., None] | None = None,
    progress: Callable[[str], None] = print,
) -> HybridOutcome:
    """The twin from K = ``permeability`` [m²], network output in units of ``noise`` [N];
    checkpoints land in ``output_dir/checkpoint.pt``; ``on_step`` sees every LM step."""
    progress("stage 3: the hybrid twin (K learnable + MLP of the model error), LM over the λ grid")
    samples, split, basis_hash = prepared.samples, prepared.split, prepared.basis.config_hash
    config = asdict(settings)
    resume = checkpoint.load_checkpoint(settings.ckpt_path, config, basis_hash) if settings.ckpt_path else None

    def save(state: dict) -> None:
        checkpoint.save_checkpoint(output_dir / "checkpoint.pt", state, config, basis_hash)

    def make_twin():
        return prepared.make_model.twin(permeability, noise, samples, split.train)

    return train_hybrid(make_twin, samples, split.train, split.val, settings.optim.hybrid, on_step, save, resume)
