"""Stored files (checkpoints, PGD bases): a flipped byte anywhere is refused, never read."""

import pytest
import torch

from ptwin import files
from ptwin.fitting import checkpoint
from ptwin.pgd.cache import cache_path, cached_basis
from tests.conftest import small_config

PLACES = (1 / 3, 1 / 2, 0.7, 0.9)


def flip(path, fraction):
    data = bytearray(path.read_bytes())
    data[int(fraction * len(data))] ^= 0x01
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("fraction", PLACES)
def test_a_checkpoint_with_one_flipped_byte_is_refused_with_one_line(tmp_path, fraction):
    path = tmp_path / "checkpoint.pt"
    state = {"theta": torch.linspace(0, 1, 5000, dtype=torch.float64), "iteration": torch.tensor(3)}
    checkpoint.save_checkpoint(path, state, {"seed": 0}, "a" * 64)
    assert torch.equal(checkpoint.load_checkpoint(path, {"seed": 0}, "a" * 64)["theta"], state["theta"])
    flip(path, fraction)
    with pytest.raises(checkpoint.CheckpointError) as error:
        checkpoint.load_checkpoint(path, {"seed": 0}, "a" * 64)
    assert str(error.value).startswith(f"ckpt_path={path}: ")
    assert "\n" not in str(error.value)


def test_a_damaged_cached_basis_is_rebuilt_with_one_line(tmp_path, small_basis):
    config = small_config()
    path = cache_path(config, tmp_path)
    small_basis.save(path)
    flip(path, 0.5)
    lines = []
    rebuilt = cached_basis(config, tmp_path, progress=lines.append)
    assert lines[0].startswith(f"cached PGD basis unusable ({path}: checksum mismatch")
    assert lines[0].endswith("rebuilding it")
    assert torch.equal(rebuilt.force.core, small_basis.force.core)
    assert files.load(path, "ptwin-pgd-basis/2", "")["config_hash"] == config.hash()  # the good file is back


def test_a_payload_must_name_its_format(tmp_path):
    with pytest.raises(ValueError, match="names its format"):
        files.save(tmp_path / "x.pt", {"data": 1})
