"""The shared development sets (``../shared/bench-sets/``): data ptwin did not write, graded by their README.

Each folder holds ``data/`` (a recording set) and ``truth.yaml`` (what is concealed and what a right
diagnosis says). Grading, as the sets' README states it:

- ``none``: no mismatch detected and nothing left out (a term only in a ``confounded`` group beside the
  base model is fine; ``unexplained`` is a false alarm);
- ``terms``: ``left_out`` names exactly the expected terms, and the corrected model's test RMSE is below
  the base model's;
- ``unexplained_or_none_wrong``: nothing left out, or ``unexplained: true``, or only terms that are
  acceptable there;

and for ``none`` and ``terms`` the corrected K within 5 % of the truth (or the set's ``k_tol``).

``make discover-bench`` runs them after its own suites (``python -m bench.discover_bench --suite
bench-sets [--only NAME ...]``: them alone). ``--suite perturbed`` runs each set again as another seed
of its family might have recorded it: every other sample (half the sampling rate), the samples between
those (the same curves, the other half of their noise), a third of every baseline cut off, the fastest
curve left out (where three or more remain): the sets are a development set, and a verdict that holds
only on their exact samples would not hold on the judged ones.

The sets are found beside the repository (``../shared/bench-sets``) or under ``$PTWIN_BENCH_SETS``;
without them the suite says so in one line and is skipped.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from hydra import compose, initialize_config_dir

from ptwin.app import typed
from ptwin.data.recordings import Meta, write_recordings
from ptwin.pipeline.run import run

ROOT = Path(__file__).resolve().parents[1]
SETS = Path(os.environ.get("PTWIN_BENCH_SETS", ROOT.parent / "shared" / "bench-sets"))


@dataclass
class Graded:
    name: str
    hides: str
    named: str
    k_error: float | None  # corrected K over the truth − 1, when the set grades K
    rmse_gain: float  # base over corrected test RMSE
    null: bool  # the set conceals nothing
    false_alarm: bool  # a null on which something was named or a mismatch declared
    seconds: float
    right: bool
    why: str  # what was wrong, empty when right

    def line(self) -> str:
        return f"{self.name}: {self.named} ({'right' if self.right else 'WRONG: ' + self.why}, {self.seconds:.1f} s)"


def grade(truth: dict, d: dict) -> tuple[bool, str, float | None]:
    """(right, why not, K error) of one diagnosis against its ``truth.yaml``."""
    expect = truth["expect"]
    named = [entry["term"] for entry in d["left_out"]]
    k_error = d["permeability"]["corrected"] / truth["K"] - 1 if d["permeability"]["corrected"] else None
    tolerance = expect.get("k_tol", 0.05)
    if expect["kind"] == "unexplained_or_none_wrong":
        acceptable = set(expect.get("also_acceptable_terms", []))
        right = not named or d["unexplained"] or set(named) <= acceptable
        return right, "" if right else f"named {', '.join(named)}", None
    problems = []
    if expect["kind"] == "none":
        if d["mismatch"]["detected"] or named:
            problems.append(f"false alarm ({', '.join(named) or ('unexplained' if d['unexplained'] else 'mismatch')})")
    else:
        if sorted(named) != sorted(expect["terms"]) or d["unexplained"]:
            problems.append(f"named {', '.join(named) or 'nothing'}{' (unexplained)' if d['unexplained'] else ''}")
        elif not d["fit"]["corrected"]["test_rmse"] < d["fit"]["base"]["test_rmse"]:
            problems.append("corrected test RMSE not below the base model's")
    if k_error is None or not abs(k_error) <= tolerance:
        problems.append(f"K off by more than {100 * tolerance:.0f}%")
    return not problems, "; ".join(problems), k_error


def diagnose_set(folder: Path, overrides: list[str], scratch: Path) -> tuple[dict, float]:
    with initialize_config_dir(config_dir=str(ROOT / "configs"), version_base="1.3"):
        cfg = compose(config_name="train", overrides=[f"data.path={folder / 'data'}", *overrides])
    started = time.perf_counter()
    diagnosis = run(typed(cfg), scratch / folder.name, progress=lambda line: None).diagnosis
    return diagnosis, time.perf_counter() - started


def shared_sets(only: list[str] | None) -> list[tuple[Path, dict]] | None:
    """(folder, truth) of every shared set whose name holds one of ``only`` (all without it); None, with a line
    saying so, when the sets are not there."""
    if not SETS.is_dir():
        print(f"bench-sets: {SETS} not found (set PTWIN_BENCH_SETS to the folder of the shared sets); skipped")
        return None
    folders = sorted(p for p in SETS.iterdir() if (p / "truth.yaml").is_file())
    chosen = [f for f in folders if not only or any(word in f.name for word in only)]
    return [(folder, yaml.safe_load((folder / "truth.yaml").read_text())) for folder in chosen]


def run_sets(overrides: list[str], scratch: Path, only: list[str] | None = None) -> list[Graded] | None:
    """Every set graded (None when the sets are not there), a line printed as each finishes."""
    sets = shared_sets(only)
    if sets is None:
        return None
    rows = []
    for folder, truth in sets:
        d, seconds = diagnose_set(folder, overrides, scratch)
        rows.append(graded(folder.name, truth, d, seconds))
        print(f"bench-sets: {rows[-1].line()}")
    return rows


def graded(name: str, truth: dict, d: dict, seconds: float) -> Graded:
    """The row of one diagnosis ``d`` of a set whose truth is ``truth``."""
    right, why, k_error = grade(truth, d)
    named = " + ".join(f"{e['term']} ({e['confidence']})" for e in d["left_out"]) or "-"
    if d["unexplained"]:
        named = f"unexplained{'' if named == '-' else ' [' + named + ']'}"
    base, corrected = d["fit"]["base"]["test_rmse"], d["fit"]["corrected"]["test_rmse"]
    null = truth["expect"]["kind"] == "none"
    return Graded(
        name=name,
        hides=" + ".join(truth.get("effects") or {}) or "-",
        named=named,
        k_error=k_error,
        rmse_gain=base / corrected if base and corrected else float("nan"),
        null=null,
        false_alarm=null and (d["mismatch"]["detected"] or bool(d["left_out"])),
        seconds=seconds,
        right=right,
        why=why,
    )


def perturbed(frame: pd.DataFrame, meta: dict):
    """(name, curves) of the set ``frame`` as other recordings of its family might be (module docstring)."""
    order = frame.groupby("curve", sort=False).cumcount()
    yield "every other sample", frame[order % 2 == 0]
    yield "the samples between", frame[order % 2 == 1]
    keep = np.ones(len(frame), dtype=bool)
    for curve in frame["curve"].unique():
        baseline = np.flatnonzero((frame["curve"] == curve).to_numpy() & (frame["z"] < 0).to_numpy())
        keep[baseline[: baseline.size // 3]] = False
    yield "a third of each baseline off", frame[keep]
    speeds = frame.groupby("curve", sort=False)["base_speed"].max()
    if speeds.size >= 4 and speeds.idxmax() != meta["reference_curve"]:
        yield "fastest curve left out", frame[frame["curve"] != speeds.idxmax()]


def run_perturbed(overrides: list[str], scratch: Path, only: list[str] | None = None) -> list[Graded] | None:
    """Every set, perturbed each way of ``perturbed``, graded against its truth."""
    sets = shared_sets(only)
    if sets is None:
        return None
    rows = []
    for folder, truth in sets:
        meta = yaml.safe_load((folder / "data" / "meta.yaml").read_text())
        for how, frame in perturbed(pd.read_csv(folder / "data" / "curves.csv"), meta):
            target = scratch / f"{folder.name}-{how.replace(' ', '-')}"  # a Hydra override's value: no commas
            write_recordings(target / "data", Meta(**{k: v for k, v in meta.items() if k != "format"}), frame)
            d, seconds = diagnose_set(target, overrides, scratch / "runs")
            rows.append(graded(f"{folder.name}, {how}", truth, d, seconds))
            print(f"perturbed: {rows[-1].line()}")
    return rows


def print_sets(
    rows: list[Graded],
    title: str = "shared bench-sets",
    source: str = "independent simulator, real noise where the set says so",
) -> None:
    print(f"\n{title} ({source})")
    width = max(34, *(len(r.name) for r in rows))
    print(f"{'set':<{width}s} {'concealed':<48s} {'named (confidence)':<52s} {'K %':>8s} {'gain':>6s} {'s':>5s}")
    for r in rows:
        k = "   –" if r.k_error is None else f"{100 * r.k_error:8.2f}"
        verdict = "right" if r.right else f"WRONG ({r.why})"
        print(
            f"{r.name:<{width}s} {r.hides:<48.48s} {r.named:<52.52s} {k:>8s} {r.rmse_gain:6.2f} {r.seconds:5.1f} "
            f"{verdict}"
        )
    nulls = [r for r in rows if r.null]
    print(f"{sum(r.right for r in rows)}/{len(rows)} sets right")
    if nulls:  # none among two terms at once (``discover_bench --suite pairs``)
        print(
            f"false alarms on the sets that conceal nothing: {sum(r.false_alarm for r in nulls)}/{len(nulls)} "
            "(the structure test's stated rate: 1%)"
        )
