"""python -m ptwin.map data.path=MAPDIR [hydra.run.dir=OUT] [map.scheduler=...] [overrides]

A force map: a folder of recording-set folders, one per spot (``position: [x, y]`` in each
meta.yaml). Every spot runs the chain of ``train.py`` (same config groups, same stages) without
the hybrid twin (``map.hybrid=true`` adds it) or the proposed next experiment, on a Dask
LocalCluster (``map.scheduler=local``, one worker per core), in this process
(``map.scheduler=serial``) or on a running Dask scheduler (``map.scheduler=tcp://host:8786``).
Writes ``spots.csv``, ``map_summary.json``, the maps as PNG and ``report.md``; each spot's result
lands in ``spots/`` as it comes, and a run in the same directory resumes from them.
"""

from __future__ import annotations

from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from ptwin.app import one_line_errors, run_face, start, typed
from ptwin.pipeline.forcemap import run_map

start(heap=False)


@hydra.main(version_base="1.3", config_path="../configs", config_name="map")
def main(cfg: DictConfig) -> None:
    output_dir = Path(HydraConfig.get().runtime.output_dir)
    with one_line_errors(output_dir):
        run_map(typed(cfg), output_dir)


if __name__ == "__main__":
    run_face(main)
