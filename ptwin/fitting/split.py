"""Train/validation/test split of the fitted samples (``Samples.fitted`` of the
non-reference curves): random over samples, or by curve (a whole speed held out)."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ptwin.physics.samples import Samples


@dataclass
class Split:
    train: torch.Tensor  # sorted sample indices
    val: torch.Tensor
    test: torch.Tensor
    held_out_curve: str | None = None

    def judged(self, samples: Samples) -> torch.Tensor:
        """The train and validation samples in contact: where a residual's structure is judged. The samples
        just before contact (``pins_contact``) are fitted, not judged: there a real force leaves the baseline
        line (long-range forces, a curved virtual deflection), which is no physics left out."""
        seen = self._seen()
        return seen[samples.in_contact[seen]]

    def pinning(self, samples: Samples) -> torch.Tensor:
        """The train and validation samples just before contact: not judged for structure, but where held-out
        samples show a contact misplaced or a drag that is not there (``ptwin.diagnosis.name.HeldOutTest``)."""
        seen = self._seen()
        return seen[samples.pins_contact[seen]]

    def _seen(self) -> torch.Tensor:
        return torch.cat([self.train, self.val]).sort().values


def check_split(fractions, mode: str) -> None:
    """``ValueError`` naming the setting where ``fractions`` are not three positive numbers summing to 1 or ``mode``
    is neither 'random' nor 'curve'."""
    if len(fractions) != 3 or min(fractions) <= 0 or abs(sum(fractions) - 1) > 1e-9:
        raise ValueError(f"split.fractions must be three positive numbers summing to 1, got {list(fractions)}")
    if mode not in ("random", "curve"):
        raise ValueError(f"split.mode must be 'random' or 'curve', got {mode!r}")


def split_samples(
    samples: Samples,
    fractions: tuple[float, float, float] = (0.70, 0.15, 0.15),
    mode: str = "random",
    held_out_curve: str | None = None,
    seed: int = 0,
) -> Split:
    """``mode='random'``: samples drawn by ``fractions``; ``mode='curve'``: the test set is the whole
    ``held_out_curve`` (default: the fastest) and train/val share the rest in the ratio of their fractions."""
    check_split(fractions, mode)
    generator = torch.Generator().manual_seed(seed)
    eligible = torch.nonzero(samples.fitted).squeeze(1)

    def shuffled(index):
        return index[torch.randperm(index.numel(), generator=generator)]

    if mode == "random":
        order = shuffled(eligible)
        n_train, n_val = int(fractions[0] * order.numel()), int(fractions[1] * order.numel())
        parts = order[:n_train], order[n_train : n_train + n_val], order[n_train + n_val :]
        return Split(*(p.sort().values for p in parts))
    if held_out_curve is None:
        held_out_curve = samples.curve_ids[int(samples.curve[samples.base_speed.argmax()])]
    if held_out_curve not in samples.curve_ids:
        raise ValueError(
            f"split.held_out_curve {held_out_curve!r} is not a fitted curve; pick one of {samples.curve_ids}"
        )
    held = samples.curve[eligible] == samples.curve_ids.index(held_out_curve)
    rest = shuffled(eligible[~held])
    n_train = int(fractions[0] / (fractions[0] + fractions[1]) * rest.numel())
    return Split(rest[:n_train].sort().values, rest[n_train:].sort().values, eligible[held], held_out_curve)
