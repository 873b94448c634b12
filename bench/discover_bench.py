"""make discover-bench: the diagnosis on recording sets with known concealed effects.

Generates (forward simulator, closed-form Darcy) sets hiding each vocabulary term at
two magnitudes, two pairs, null sets of three geometries and one effect outside the
vocabulary; runs the pipeline of train.py on each; prints expected vs named
terms, the K error before/after correction, the test-RMSE gain and the run time.
"""

from __future__ import annotations

import argparse
import os
import re
import tempfile
import time
import warnings
from pathlib import Path

from hydra import compose, initialize_config_dir

from ptwin.app import register, typed
from ptwin.data.recordings import write_recordings
from ptwin.pipeline.run import run
from ptwin.synth.simulator import Experiment, simulate

ROOT = Path(__file__).resolve().parents[1]
CASES = [
    ("null", {}, {}),
    ("null, probe 5 µm", {}, {"probe_radius": 5.0e-6, "z_end": 2.0e-6}),
    ("null, thin film 15 µm", {}, {"sample_thickness": 15.0e-6}),
    ("viscosity small", {"solid_viscosity": {"gamma": 2.0}}, {}),
    ("viscosity large", {"solid_viscosity": {"gamma": 10.0}}, {}),
    ("relaxation small", {"solid_relaxation": {"g": 0.05, "tau": 0.5}}, {}),
    ("relaxation large", {"solid_relaxation": {"g": 0.2, "tau": 0.5}}, {}),
    ("pore small", {"pore_pressure_relaxation": {"M": 1.0e5}}, {}),
    ("pore large", {"pore_pressure_relaxation": {"M": 3.0e4}}, {}),
    ("strain perm. small", {"strain_dependent_permeability": {"m": 0.5}}, {}),
    ("strain perm. large", {"strain_dependent_permeability": {"m": 2.0}}, {}),
    ("drag small", {"cantilever_drag": {"b": 2.0e-5}}, {}),
    ("drag large", {"cantilever_drag": {"b": 1.0e-4}}, {}),
    ("offset small", {"contact_offset": {"delta": 0.05e-6}}, {}),
    ("offset large", {"contact_offset": {"delta": 0.15e-6}}, {}),
    ("pair pore + viscosity", {"pore_pressure_relaxation": {"M": 3.0e4}, "solid_viscosity": {"gamma": 5.0}}, {}),
    ("pair strain + drag", {"strain_dependent_permeability": {"m": 2.0}, "cantilever_drag": {"b": 1.0e-4}}, {}),
    ("outside: force drift", {"force_drift": {"rate": 0.3e-9}}, {}),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=1000, help="samples per curve")
    parser.add_argument("--pgd", default="default", help="PGD preset")
    parser.add_argument("--only", nargs="*", help="run only the cases whose name contains one of these")
    args = parser.parse_args()
    warnings.filterwarnings("ignore", category=RuntimeWarning)
    register()
    cache = os.environ.get("PTWIN_CACHE", str(ROOT / ".cache" / "ptwin"))
    cases = [c for c in CASES if not args.only or any(word in c[0] for word in args.only)]
    rows, right = [], 0
    with tempfile.TemporaryDirectory() as scratch:
        for name, effects, geometry in cases:
            experiment = Experiment(samples=args.samples, effects=effects, **geometry)
            folder = Path(scratch) / re.sub(r"[^A-Za-z0-9]+", "_", name)
            write_recordings(folder, *simulate(experiment))
            with initialize_config_dir(config_dir=str(ROOT / "configs"), version_base="1.3"):
                cfg = compose(
                    config_name="train", overrides=[f"data.path={folder}", f"pgd={args.pgd}", f"cache_dir={cache}"]
                )
            started = time.perf_counter()
            d = run(typed(cfg), folder / "run").diagnosis
            seconds = time.perf_counter() - started
            expected = sorted(t for t in effects if t != "force_drift")
            named = sorted(entry["term"] for entry in d["left_out"])
            outside = "force_drift" in effects
            correct = d["unexplained"] and not named if outside else (named == expected and not d["unexplained"])
            right += correct
            k = experiment.permeability
            rows.append(
                (
                    name,
                    "unexplained" if outside else " + ".join(expected) or "-",
                    ("unexplained" if d["unexplained"] else "") + " + ".join(named) or "-",
                    100 * (d["permeability"]["base"] / k - 1),
                    100 * (d["permeability"]["corrected"] / k - 1),
                    d["fit"]["base"]["test_rmse"] / d["fit"]["corrected"]["test_rmse"],
                    seconds,
                    "right" if correct else "WRONG",
                )
            )
    print()
    print(f"{'case':<24s} {'expected':<50s} {'named':<50s} {'K base %':>9s} {'K corr %':>9s} {'gain':>6s} {'s':>5s}")
    for row in rows:
        case, expected, named, *figures, verdict = row
        print(
            f"{case:<24s} {expected:<50s} {named:<50s} {figures[0]:9.2f} {figures[1]:9.2f} {figures[2]:6.2f} "
            f"{figures[3]:5.1f} {verdict}"
        )
    biased = [r for r in rows if abs(r[3]) > 3 and r[7] == "right" and r[2] not in ("-", "unexplained")]
    within = sum(abs(r[4]) <= 3 for r in biased)
    print(
        f"\n{right}/{len(rows)} cases right; corrected K within 3% in {within}/{len(biased)} cases where the base K "
        f"was biased by more than 3%; median time {sorted(r[6] for r in rows)[len(rows) // 2]:.1f} s"
    )


if __name__ == "__main__":
    main()
