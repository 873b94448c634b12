"""python -m ptwin.inject data.path=SET inject.term=TERM inject.values=[…] inject.sizes=[…] [overrides]
python -m ptwin.inject data.path=SET inject.term=all [overrides]

What the user's own recordings could have shown: the term added to them through the
cantilever balance (everything else as recorded; method and limits in ``ptwin.pipeline.inject``), at
each size, and diagnosed as ``train.py`` would. Writes ``as-recorded/`` (the recordings' own run, its
report.md ending with the section on what they could have shown) and ``size-<s>/`` (the recordings
with the term added, and their run) under the run directory. With ``inject.term=all``, every candidate
term at growing sizes until named (``<term>-peak-<p>/``), and the report's section gives each term's
smallest size named.
"""

from __future__ import annotations

from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from ptwin.app import one_line_errors, run_face, start, typed
from ptwin.pipeline.inject import detection, detection_limits
from ptwin.pipeline.settings import EVERY_TERM

start()


@hydra.main(version_base="1.3", config_path="../configs", config_name="inject")
def main(cfg: DictConfig) -> None:
    output_dir = Path(HydraConfig.get().runtime.output_dir)
    with one_line_errors(output_dir):
        settings = typed(cfg)
        (detection_limits if settings.inject.term == EVERY_TERM else detection)(settings, output_dir)


if __name__ == "__main__":
    run_face(main)
