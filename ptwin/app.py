"""What the Hydra faces share (``train.py``, ``python -m ptwin.pgd``): the typed settings
registered as the configs' schema, their conversion to dataclasses, and one line with
exit code 2 for every error a user can fix (bad recordings, a damaged or foreign
checkpoint, an impossible setting)."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, OmegaConf

from ptwin.data.recordings import RecordingError
from ptwin.files import StoredFileError
from ptwin.pgd.config import PGDConfig
from ptwin.pipeline.settings import Settings


@dataclass
class BuildSettings:
    """``configs/pgd_build.yaml``: ``python -m ptwin.pgd``."""

    pgd: PGDConfig = field(default_factory=PGDConfig)
    out: str | None = None  # default: the cache, where train.py looks
    cache_dir: str = ".cache/ptwin"


class SettingsError(ValueError):
    """A setting that composes but cannot be run; the message names it and the fix."""


def register() -> None:
    """Register the primary configs' schemas (``train_schema``, ``pgd_build_schema``)."""
    store = ConfigStore.instance()
    store.store(name="train_schema", node=Settings)
    store.store(name="pgd_build_schema", node=BuildSettings)


def typed(cfg: DictConfig):
    """The composed config as its schema's dataclass (``Settings`` or ``BuildSettings``)."""
    try:
        return OmegaConf.to_object(cfg)
    except ValueError as error:
        raise SettingsError(str(error).splitlines()[0]) from None


@contextmanager
def user_errors_exit_2() -> Iterator[None]:
    """Errors a user can fix end the run with their one line on stderr and exit code 2."""
    try:
        yield
    except (RecordingError, StoredFileError, SettingsError) as error:
        print(error, file=sys.stderr)
        raise SystemExit(2) from None
