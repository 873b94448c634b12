"""make discover-bench (part): estimated baselines' levels under real recorded noise. How often a drag stays in the
force, and how often levels of a set without one are taken for drag.

Where contacts are estimated, each curve's own level is removed unless the levels are one common level plus drag
that rises with speed beyond their scatter (``ptwin.data.contact.LevelsWithSpeed``); each level's error is its
baseline's noise and the drift the set's baseline slopes show (``ptwin.data.contact.drifted``). Kept, the drag stays
in the force and ``cantilever_drag`` is a candidate; taken for drag, a null keeps its curves' offsets in the force.

The bench-sets' p04/p06 setting (four speeds, contacts estimated from 0.8 µm of baseline, the noise scaled to 0.2
nN) is simulated with p08's drag (1e-4 N s/m) and without, each curve given a window of one material's public
records (``bench.real_noise``), at seeds 1 to N. Only the kinematics are read: a second or two a set.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from bench.discover_bench import ESTIMATED_REAL, _positive
from bench.real_noise import noise_records, with_real_noise
from ptwin.data.kinematics import CurveKinematics, curve_kinematics
from ptwin.data.recordings import load_recordings, write_recordings
from ptwin.synth.simulator import Experiment

DRAG = 1e-4  # [N s/m] p08's


def kinematics(records: list, seed: int, drag: float, folder: Path) -> list[CurveKinematics]:
    """The curves of the set of ``seed`` (``drag`` [N s/m] concealed, noise windows of ``records``), written to
    ``folder`` and read back, their baselines estimated."""
    effects = {"cantilever_drag": {"b": drag}} if drag else {}
    meta, curves = with_real_noise(Experiment(seed=seed, effects=effects, **ESTIMATED_REAL), records)
    write_recordings(folder, meta, curves)
    return curve_kinematics(load_recordings(folder))


def common_level(records: list, seed: int, drag: float, folder: Path) -> bool:
    """Whether that set has only its common level removed: its levels read as one level plus a drag."""
    return all(curve.baseline.common for curve in kinematics(records, seed, drag, folder))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=_positive, default=12, help="sets per material, with the drag and without")
    args = parser.parse_args()
    records = noise_records()
    if records is None:
        return
    print(f"\nestimated baselines' levels under real noise (p04/p06's setting, seeds 1–{args.seeds})")
    with tempfile.TemporaryDirectory() as scratch:
        for material, windows in records.items():
            counts = {}
            for drag in (DRAG, 0.0):
                folders = (Path(scratch) / f"{material}-{drag:g}-{seed}" for seed in range(1, args.seeds + 1))
                counts[drag] = sum(common_level(windows, s, drag, f) for s, f in enumerate(folders, start=1))
            print(
                f"  {material}: a drag of {DRAG:g} N s/m kept in the force at {counts[DRAG]} of {args.seeds}; "
                f"sets without one taken for drag at {counts[0.0]} of {args.seeds}",
                flush=True,
            )


if __name__ == "__main__":
    main()
