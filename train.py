"""python train.py [overrides]: the ptwin chain on a recording set (default: the bundled demo).

Reads and checks the recording set, reuses (or builds once) the cached PGD basis, runs
the paper's identification chain (stage 1: global and pointwise K; stage 2: K with the
viscous term; stage 3: the hybrid twin) and the diagnosis of what physics the base
model left out. Everything lands in the run directory (results.json, diagnosis.json,
report.md, figures, TensorBoard events, checkpoint.pt); the stages are
``ptwin.pipeline``. Bad input ends the run with one line and exit code 2 (anything
unforeseen: one line, exit code 3, the traceback in the run directory's error.log).
"""

from __future__ import annotations

from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from ptwin.app import exit_now, one_line_errors, run_face, start, typed
from ptwin.pipeline.run import run

start()


@hydra.main(version_base="1.3", config_path="configs", config_name="train")
def main(cfg: DictConfig) -> None:
    output_dir = Path(HydraConfig.get().runtime.output_dir)
    with one_line_errors(output_dir):
        run(typed(cfg), output_dir)


if __name__ == "__main__":
    run_face(main)
    exit_now()
