"""Stage 3 (paper §5.3): the hybrid twin, K learnable next to an MLP of the model error,
trained by LM over the λ grid with checkpoints (``ckpt_path`` resumes); in a run on one set, trained aside
(``TwinAside``) while the diagnosis fits what does not need it."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, fields
from functools import partial
from pathlib import Path

from ptwin.aside import Aside, can_fork
from ptwin.fitting import checkpoint
from ptwin.fitting.hybrid import HybridTwin
from ptwin.fitting.hybrid_training import HybridOutcome, train_hybrid
from ptwin.pipeline.drawing import Drawing
from ptwin.pipeline.prepare import Prepared
from ptwin.pipeline.settings import Settings
from ptwin.reporting.tensorboard import TrainingLog


def train_twin(
    prepared: Prepared,
    permeability: float,
    noise: float,
    settings: Settings,
    output_dir: Path,
    on_step: Callable[..., None] | None = None,
) -> HybridOutcome:
    """The twin from K = ``permeability`` [m²], network output in units of ``noise`` [N];
    checkpoints land in ``output_dir/checkpoint.pt``; ``on_step`` sees every LM step."""
    samples, split, basis_hash = prepared.samples, prepared.split, prepared.basis.config_hash
    config = asdict(settings)
    resume = checkpoint.load_checkpoint(settings.ckpt_path, config, basis_hash) if settings.ckpt_path else None

    def save(state: dict) -> None:
        checkpoint.save_checkpoint(output_dir / "checkpoint.pt", state, config, basis_hash)

    return train_hybrid(
        _twin_maker(prepared, permeability, noise),
        samples,
        split.train,
        split.val,
        settings.optim.hybrid,
        on_step,
        save,
        resume,
    )


def _twin_maker(prepared: Prepared, permeability: float, noise: float) -> Callable[[], HybridTwin]:
    return lambda: prepared.make_model.twin(permeability, noise, prepared.samples, prepared.split.train)


class TwinAside:
    """``train_twin`` aside (``ptwin.aside``), its LM steps logged to TensorBoard (``output_dir/tensorboard``) where
    it trains; ``outcome()`` waits for it. The twin comes back as its parameters and is rebuilt here from the same
    start, so it predicts what the trained one did, bit for bit. ``draw``: figures of the trained twin (twin →
    {name: its PNG file}, its lines said through the progress it is given), drawn aside too once the twin is here, while
    the caller goes on; ``drawn()`` waits for them. A progress bar only where nothing else is said meanwhile: where
    the twin trains here, when first asked for. Leave it as a context manager: work aside that is still going when
    the caller fails is stopped."""

    def __init__(
        self,
        prepared: Prepared,
        permeability: float,
        noise: float,
        settings: Settings,
        output_dir: Path,
        progress: Callable[[str], None] = print,
        draw: Callable[[HybridTwin, Callable[[str], None]], dict] | None = None,
    ):
        forked = can_fork()
        aside = " (aside, while the diagnosis fits what does not need it)" if forked else ""
        progress(f"stage 3: the hybrid twin (K learnable + MLP of the model error), LM over the λ grid{aside}")
        samples, split = prepared.samples, prepared.split
        self._make_twin, self._outcome = _twin_maker(prepared, permeability, noise), None
        self._draw, self._drawing, self._forked, self._progress = draw, Drawing(), forked, progress

        def trained() -> tuple[dict, dict]:
            hybrid = settings.optim.hybrid
            log = TrainingLog(
                output_dir / "tensorboard", samples, split.train, split.val, noise, hybrid, bar=not forked
            )
            outcome = train_twin(prepared, permeability, noise, settings, output_dir, log.on_step)
            log.end_training()
            rest = {f.name: getattr(outcome, f.name) for f in fields(outcome) if f.name != "twin"}
            return outcome.twin.state_dict(), rest

        self._aside = Aside(trained, fork=forked)

    def outcome(self) -> HybridOutcome:
        if self._outcome is None:
            state, rest = self._aside.result()
            twin = self._make_twin()
            twin.load_state_dict(state)
            self._outcome = HybridOutcome(twin=twin, **rest)
            if self._draw is not None:
                self._drawing.start(partial(self._draw, twin), fork=self._forked)
        return self._outcome

    def twin(self) -> HybridTwin:
        return self.outcome().twin

    def drawn(self) -> dict:
        """What ``draw`` drew of the trained twin ({} without ``draw``), its lines said now."""
        self.outcome()
        return self._drawing.figures(self._progress)

    def __enter__(self) -> TwinAside:
        return self

    def __exit__(self, *exc) -> None:
        self._aside.__exit__(*exc)
        self._drawing.__exit__(*exc)
