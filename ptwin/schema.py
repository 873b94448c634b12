"""Hydra schema: dataclasses registered in the ConfigStore, so that a typo or a wrong
type fails at the command line. Only entry points (train.py, the CLIs) import this."""

from __future__ import annotations

from hydra.core.config_store import ConfigStore

from ptwin.pgd.config import PGDConfig


def register() -> None:
    ConfigStore.instance().store(group="pgd", name="schema", node=PGDConfig)
