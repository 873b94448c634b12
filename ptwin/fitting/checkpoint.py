"""Checkpoints: explicit plain dicts, stored through ``ptwin.files`` (atomic, checksummed,
loaded with ``weights_only=True``).

A checkpoint carries the run's configuration and the PGD basis hash; resuming under
another configuration or basis is refused, naming the first difference.
"""

from __future__ import annotations

from pathlib import Path

import torch

from ptwin import files

FORMAT = "ptwin-checkpoint/2"
IGNORED_KEYS = ("ckpt_path", "cache_dir")  # where things live, not what is computed


class CheckpointError(files.StoredFileError):
    pass


def rng_states() -> dict:
    states = {"torch": torch.get_rng_state()}
    if torch.cuda.is_available():
        states["cuda"] = torch.cuda.get_rng_state_all()
    return states


def save_checkpoint(path: str | Path, state: dict, config: dict, basis_hash: str) -> None:
    """Write ``state`` with its provenance; a kill at any moment leaves the previous file intact."""
    files.save(
        path, {"format": FORMAT, "config": config, "basis_hash": basis_hash, "rng": rng_states(), "state": state}
    )


def _first_difference(saved, current, prefix=""):
    if isinstance(saved, dict) and isinstance(current, dict):
        for key in sorted(set(saved) | set(current)):
            if not prefix and key in IGNORED_KEYS:
                continue
            found = _first_difference(saved.get(key), current.get(key), f"{prefix}{key}.")
            if found:
                return found
        return None
    return None if saved == current else f"{prefix.rstrip('.')}: checkpoint {saved!r}, now {current!r}"


def load_checkpoint(path: str | Path, config: dict, basis_hash: str) -> dict:
    """The state saved at ``path``, after checking it belongs to this configuration and basis."""
    remedy = "give the checkpoint.pt of a run, or start afresh without ckpt_path"
    payload = files.load(path, FORMAT, remedy, label=f"ckpt_path={path}", error=CheckpointError)
    if payload["basis_hash"] != basis_hash:
        raise CheckpointError(
            f"ckpt_path={path}: written with PGD basis {payload['basis_hash'][:16]}, this run uses "
            f"{basis_hash[:16]}; resume with the same pgd settings"
        )
    difference = _first_difference(payload["config"], config)
    if difference:
        raise CheckpointError(
            f"ckpt_path={path}: incompatible configuration ({difference}); resume with the same overrides"
        )
    torch.set_rng_state(payload["rng"]["torch"])
    if "cuda" in payload["rng"] and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(payload["rng"]["cuda"])
    return payload["state"]
