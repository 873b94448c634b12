"""make discover-bench: the diagnosis on recording sets with known concealed effects.

Four suites of its own, each a table, then the shared development sets (``bench/bench_sets.py``):

- ``original``: sets hiding each vocabulary term at two magnitudes, two pairs, null sets
  of three geometries and one effect outside the vocabulary (stiff cantilever, five
  speeds over two decades, white noise, known contact);
- ``realism``: what real recordings have — correlated noise, contact points to estimate
  under a tilted, offset baseline, a soft cantilever at three speeds a factor 3 apart,
  two speeds, replicates, spots of different stiffness — nulls and each term;
- ``loop``: soft-cantilever sets whose approach curves leave candidates confounded; the
  next experiments ptwin proposes (for its confounded groups and its terms below strong),
  recorded from the same truth; ptwin again, round after round (at most three). Right:
  the concealed term named strong with K within 5%;
- ``rheology``: power-law rheology on five speeds (α within 10% too), the hereditary
  terms with a ramp-and-hold beside the approaches, a weak power law on a soft
  cantilever at three speeds (right: confounded with the base model, K interval covering
  the truth, the separating experiment proposed), each relaxation (and none) in one
  ramp-and-hold curve alone, the standard stress relaxation of a spot, and protocols mixed
  in one set (approaches, a stress relaxation and a creep).

Beside them, not in ``all`` (``--suite seeds``, ~60 diagnoses): the false-alarm rate and the detection rate
over seeds, on nulls and on sets with a pore relaxation in the bench-sets' p01/p07 setting (their AR(1) noise
with a white floor, 0.3 µm of baseline, the noise std in meta.yaml), with the block inflation each null's
diagnosis used beside the one the noise was drawn with. ``--suite real-noise`` (not in ``all``, ~150 diagnoses, the
public curves of ``$PTWIN_OPEN_DATA`` read): the same rates with real recorded noise in place of the simulator's
(``bench/real_noise.py``), on nulls in the soft-cantilever setting, on nulls and pore sets in p07's, and on nulls
and solid relaxations in p04's and p06's. ``--suite families`` (not in ``all``, 25 diagnoses a seed, 3 seeds unless
``--seeds`` says): the shared sets' families drawn again by ptwin's simulator (``FAMILIES``), graded by their README.
``--suite pairs`` (not in ``all``, 10 diagnoses a seed): two terms at once in those families' settings (``PAIRS``),
graded alike.
``--seed N`` draws the four suites' noise from another seed (0 gives the tables of record): the same families as
other recordings of them would be.

A case is right when the named terms are the concealed ones (nulls: none, and nothing called unexplained
where noise alone is left, as ``bench_sets`` grades; the outside effect: unexplained) with K within 5%; or,
honestly, when nothing is claimed beyond weak names and the concealed term is in a confounded group (with the
base model, or with the weak name) whose K interval covers the truth; or, for a term the setting cannot identify
(solid_viscosity with estimated contacts), when nothing is claimed. With estimated contacts a concealed drag may
go with the baselines or be named (``REMOVED_WITH_ESTIMATED_CONTACT``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import tempfile
import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir

from bench.bench_sets import Graded, graded, print_sets, run_perturbed, run_sets
from bench.real_noise import noise_records, with_real_noise
from ptwin.app import register, typed
from ptwin.data.noise import model_inflation
from ptwin.data.recordings import write_recordings
from ptwin.pipeline.run import run
from ptwin.synth.presets import SOFT_CANTILEVER
from ptwin.synth.simulator import Experiment, Hold, simulate

ROOT = Path(__file__).resolve().parents[1]


@dataclass
class Case:
    name: str
    effects: dict = field(default_factory=dict)
    setting: dict = field(default_factory=dict)
    identifiable: bool = True  # False: the setting cannot name it; right is claiming nothing
    params_within: float | None = None  # named right also needs each concealed parameter within this fraction
    proposes: bool = False  # confounded right also needs a proposed next experiment for the concealed term
    noise_in_meta: bool = False  # the noise std written in meta.yaml, as a lab that measured it writes it

    @property
    def noise_alone(self) -> bool:
        """A null whose residual is noise alone under the base model: what the structure test's stated rate is of.
        Replicates of differing stiffness (``stiffness_spread``) conceal no term but do leave structure."""
        return not self.effects and not self.setting.get("stiffness_spread")


ORIGINAL = [
    Case("null"),
    Case("null, probe 5 µm", setting={"probe_radius": 5.0e-6, "z_end": 2.0e-6}),
    Case("null, thin film 15 µm", setting={"sample_thickness": 15.0e-6}),
    Case("viscosity small", {"solid_viscosity": {"gamma": 2.0}}),
    Case("viscosity large", {"solid_viscosity": {"gamma": 10.0}}),
    Case("relaxation small", {"solid_relaxation": {"g": 0.05, "tau": 0.5}}),
    Case("relaxation large", {"solid_relaxation": {"g": 0.2, "tau": 0.5}}),
    Case("pore small", {"pore_pressure_relaxation": {"M": 1.0e5}}),
    Case("pore large", {"pore_pressure_relaxation": {"M": 3.0e4}}),
    Case("strain perm. small", {"strain_dependent_permeability": {"m": 0.5}}),
    Case("strain perm. large", {"strain_dependent_permeability": {"m": 2.0}}),
    Case("drag small", {"cantilever_drag": {"b": 2.0e-5}}),
    Case("drag large", {"cantilever_drag": {"b": 1.0e-4}}),
    Case("offset small", {"contact_offset": {"delta": 0.05e-6}}),
    Case("offset large", {"contact_offset": {"delta": 0.15e-6}}),
    Case("pair pore + viscosity", {"pore_pressure_relaxation": {"M": 3.0e4}, "solid_viscosity": {"gamma": 5.0}}),
    Case("pair strain + drag", {"strain_dependent_permeability": {"m": 2.0}, "cantilever_drag": {"b": 1.0e-4}}),
    Case("outside: force drift", {"force_drift": {"rate": 0.3e-9}}),
]

# A stiff cantilever at five speeds with correlated noise and a long baseline; with the contact to estimate.
CORRELATED = {"z_start": -1.0e-6, "noise_correlation": 0.5}
ESTIMATED = {**CORRELATED, "contact_point": "estimate", "contact_error": 1e-7, "baseline_offset": 1e-9, "tilt": 1e-3}
SOFT = SOFT_CANTILEVER
# The bench-sets' p01/p07 setting: four speeds over 1.8 decades, known contacts, 0.3 µm of baseline, the noise
# std written in meta.yaml, AR(1) noise of 20-sample memory with 40% of its variance white.
SEEDED = {
    "probe_radius": 10e-6,
    "spring_constant": 2.0,
    "sample_thickness": 5e-3,
    "permeability": 3e-16,
    "effective_modulus": 1.5e4,
    "base_speeds": (1e-6, 4e-6, 16e-6, 64e-6),
    "samples": 1500,
    "z_start": -0.3e-6,
    "z_end": 2.65e-6,
    "noise_std": 2.5e-10,
    "noise_correlation": math.exp(-1.0 / 20.0),
    "noise_white_share": 0.4,
}
# The bench-sets' p04/p06 setting: p07's probe and speeds, contacts estimated from 0.8 µm of baseline, the noise std
# (what real noise is scaled to) written in meta.yaml.
ESTIMATED_REAL = {
    **{key: value for key, value in SEEDED.items() if not key.startswith("noise_")},
    "z_start": -0.8e-6,
    "z_end": 2.63e-6,
    "noise_std": 2.0e-10,
    "contact_point": "estimate",
    "contact_error": 1e-7,
}
REALISM = [
    Case("null, correlated noise", setting=CORRELATED),
    Case("null, estimated contact, tilt", setting={**ESTIMATED, "noise_correlation": 0.7}),
    Case("null, soft, 3 speeds", setting=SOFT),
    Case("null, soft, 2 speeds", setting={**SOFT, "base_speeds": (5e-6, 15e-6)}),
    Case("null, soft, replicates", setting={**SOFT, "replicates": 2}),
    Case("null, soft, spots ±10%", setting={**SOFT, "replicates": 2, "stiffness_spread": 0.1}),
    Case("viscosity, estimated", {"solid_viscosity": {"gamma": 10.0}}, ESTIMATED, identifiable=False),
    Case("relaxation, estimated", {"solid_relaxation": {"g": 0.2, "tau": 0.5}}, ESTIMATED),
    Case("pore, estimated", {"pore_pressure_relaxation": {"M": 3.0e4}}, ESTIMATED),
    Case("strain perm., estimated", {"strain_dependent_permeability": {"m": 2.0}}, ESTIMATED),
    Case("drag, estimated (removed)", {"cantilever_drag": {"b": 1.0e-4}}, ESTIMATED),
    Case("viscosity, soft", {"solid_viscosity": {"gamma": 5.0}}, SOFT, identifiable=False),
    Case("relaxation, soft", {"solid_relaxation": {"g": 0.1, "tau": 0.1}}, SOFT),
    Case("pore, soft", {"pore_pressure_relaxation": {"M": 5.0e3}}, SOFT),
    Case("strain perm., soft", {"strain_dependent_permeability": {"m": 2.0}}, SOFT),
    Case("outside: drift, correlated", {"force_drift": {"rate": 0.3e-9}}, CORRELATED),
    # Known contacts, a short baseline and the noise std in meta.yaml, as p09 has them. A contact moved where the
    # recording says none can be took the drag and the viscosity. p09's pair at half its values passed for noise
    # (2.8× its std in RMS) until the pair's residual capped the baselines' long reading of the noise's correlation
    # (stop 114, README "make discover-bench"). At 5/8 of its values it was read as a drag with the strain-dependent
    # K, strong, until the samples before a known contact were fitted (a drag offsets them).
    Case(
        "pair drag + viscosity, AR(1)",
        {"cantilever_drag": {"b": 1.0e-4}, "solid_viscosity": {"gamma": 12.0}},
        SEEDED,
        noise_in_meta=True,
    ),
    Case(
        "pair viscosity + strain perm., AR(1)",
        {"solid_viscosity": {"gamma": 6.0}, "strain_dependent_permeability": {"m": 1.0}},
        SEEDED,
        noise_in_meta=True,
    ),
    Case(
        "pair viscosity + strain perm. 5/8 p09",
        {"solid_viscosity": {"gamma": 7.5}, "strain_dependent_permeability": {"m": 1.4}},
        SEEDED,
        noise_in_meta=True,
    ),
    # p07's pore beside a viscosity: the viscosity alone passes the whole-residual test, the pore alone does
    # nothing, and the pair was never fitted until the best single was grown by one term each (the forward step).
    Case(
        "pair pore + viscosity, AR(1)",
        {"pore_pressure_relaxation": {"M": 5.0e4}, "solid_viscosity": {"gamma": 12.0}},
        SEEDED,
        noise_in_meta=True,
    ),
]
# The loop: approach curves that leave candidates confounded; the proposed next experiments (the confounded
# groups' and those of terms named below strong), recorded from the same truth; the diagnosis again, for at
# most ROUNDS rounds. Right: the concealed term named strong, K within 5%.
ROUNDS = 3
LOOP = [
    Case("relaxation vs pore, soft", {"solid_relaxation": {"g": 0.1, "tau": 0.1}}, SOFT),
    Case("pore vs base, soft", {"pore_pressure_relaxation": {"M": 5.0e3}}, SOFT),
    Case("strain perm. vs base, soft", {"strain_dependent_permeability": {"m": 2.0}}, SOFT),
    Case("power law vs base, soft", {"power_law_rheology": {"alpha": 0.03}}, SOFT),
]
# Power-law rheology: named with its exponent on five speeds; with holds, each hereditary term named and none
# claiming another's data; weak on a soft cantilever at three speeds, where a smaller K fits as well.
HOLD = {"holds": (Hold(2.0e-6, 1.0, 8.0e-6),)}
# One ramp-and-hold curve and nothing else: the standard stress relaxation of a spot.
ONE_CURVE = {"base_speeds": (), "holds": (Hold(3.0e-6, 3.0, 10.0e-6),), "z_start": -3.0e-6, "sample_rate": 2000.0}
# Protocols mixed in one set: approaches at two speeds, a stress relaxation and a creep on the same spot.
MIXED = {"base_speeds": (2.0e-6, 20.0e-6), "holds": (Hold(2.0e-6, 1.0, 8.0e-6), Hold(2.0e-6, 1.0, 8.0e-6, creep=True))}
RHEOLOGY = [
    Case("power law, five speeds", {"power_law_rheology": {"alpha": 0.1}}, params_within=0.1),
    Case("power law, hold", {"power_law_rheology": {"alpha": 0.1}}, HOLD, params_within=0.1),
    Case("relaxation, hold", {"solid_relaxation": {"g": 0.2, "tau": 0.5}}, HOLD),
    Case("pore, hold", {"pore_pressure_relaxation": {"M": 3.0e4}}, HOLD),
    Case("weak power law, soft", {"power_law_rheology": {"alpha": 0.03}}, SOFT, proposes=True),
    Case("relaxation, one ramp-and-hold", {"solid_relaxation": {"g": 0.2, "tau": 0.5}}, ONE_CURVE),
    Case("pore, one ramp-and-hold", {"pore_pressure_relaxation": {"M": 3.0e4}}, ONE_CURVE),
    Case("power law, one ramp-and-hold", {"power_law_rheology": {"alpha": 0.1}}, ONE_CURVE, params_within=0.1),
    Case("null, one ramp-and-hold", setting=ONE_CURVE),
    Case("relaxation, hold + creep", {"solid_relaxation": {"g": 0.2, "tau": 0.5}}, MIXED),
    Case("pore, hold + creep", {"pore_pressure_relaxation": {"M": 3.0e4}}, MIXED),
]
SUITES = {"original": ORIGINAL, "realism": REALISM, "loop": LOOP, "rheology": RHEOLOGY}
SEEDED_TERM = {"pore_pressure_relaxation": {"M": 5.0e4}}  # p07's
# With estimated contacts the offset is fitted as a nuisance, and a drag is removed with each curve's own baseline
# level where the levels cannot tell it from free offsets, kept in the force and named where they show one level
# plus b·speed (the shared p08, four speeds): either is right.
REMOVED_WITH_ESTIMATED_CONTACT = {"cantilever_drag", "contact_offset"}


def verdict(case: Case, experiment: Experiment, d: dict) -> bool:
    """Right or wrong, by the rules of the module docstring."""
    named = sorted(entry["term"] for entry in d["left_out"])
    expected = sorted(t for t in case.effects if t != "force_drift")
    if experiment.contact_point == "estimate":
        expected = [t for t in expected if t not in REMOVED_WITH_ESTIMATED_CONTACT]
        named = [t for t in named if t not in REMOVED_WITH_ESTIMATED_CONTACT or t not in case.effects]
    if "force_drift" in case.effects:
        return d["unexplained"] and not named
    if not expected:  # a null: nothing named, and where noise alone is left, no structure called unexplained
        return not named and not (case.noise_alone and d["unexplained"])
    if not case.identifiable:  # nothing claimed, or the right name with weak confidence
        return not named or (named == expected and all(e["confidence"] == "weak" for e in d["left_out"]))
    k = relative_error(d["permeability"]["corrected"], experiment.permeability)
    if named == expected:
        return abs(k) <= 0.05 and parameters_within(case, d)
    low, high = d["permeability"]["corrected_interval"]
    covers = low is not None and high is not None and low <= experiment.permeability <= high
    groups = [g for g in d["confounded"] if set(expected) & group_terms(g)]
    weak = all(entry["confidence"] == "weak" for entry in d["left_out"])
    proposed = not case.proposes or any("next_experiment" in g for g in groups)
    return weak and set(expected) <= {n for g in groups for n in group_terms(g)} | set(named) and covers and proposed


def group_terms(group: dict) -> set[str]:
    """The terms of a confounded group, each of its subsets read term by term ("a + b" is a and b)."""
    return {term for label in group["terms"] for term in label.split(" + ")}


def relative_error(permeability: float | None, truth: float) -> float:
    """K's error relative to the truth; infinite where the diagnosis gives no K (its fit left no fluid force)."""
    return math.inf if permeability is None else permeability / truth - 1


def parameters_within(case: Case, d: dict) -> bool:
    if case.params_within is None:
        return True
    fitted = {entry["term"]: entry["params"] for entry in d["left_out"]}
    return all(
        abs(fitted[term][name] / value - 1) <= case.params_within
        for term, params in case.effects.items()
        for name, value in params.items()
    )


def row(case: Case, experiment: Experiment, d: dict, seconds: float) -> tuple:
    named = " + ".join(f"{e['term']} ({e['confidence']})" for e in d["left_out"])
    if d["unexplained"]:
        named = f"unexplained [{named}]" if named else "unexplained"
    truth = experiment.permeability
    low, high = d["permeability"]["corrected_interval"]
    covers = "–" if low is None or high is None else ("yes" if low <= truth <= high else "no")
    confounded = "; ".join(" ~ ".join(g["terms"]) for g in d["confounded"]) or "-"
    return (
        case.name,
        " + ".join(t for t in case.effects) or "-",
        named or "-",
        confounded,
        100 * relative_error(d["permeability"]["base"], truth),
        100 * relative_error(d["permeability"]["corrected"], truth),
        covers,
        seconds,
        "right" if verdict(case, experiment, d) else "WRONG",
    )


def print_table(title: str, rows: list[tuple]) -> None:
    print(f"\n{title}")
    print(
        f"{'case':<30s} {'concealed':<40s} {'named (confidence)':<48s} {'confounded':<48s} {'K base %':>9s} "
        f"{'K corr %':>9s} {'covers':>6s} {'s':>5s}"
    )
    for case, concealed, named, confounded, base, corrected, covers, seconds, right in rows:
        print(
            f"{case:<30s} {concealed:<40.40s} {named:<48.48s} {confounded:<48.48s} {base:9.2f} {corrected:9.2f} "
            f"{covers:>6s} {seconds:5.1f} {right}"
        )
    right = sum(r[-1] == "right" for r in rows)
    print(f"{right}/{len(rows)} cases right; median time {sorted(r[-2] for r in rows)[len(rows) // 2]:.1f} s")


def diagnose(
    experiment: Experiment,
    folder: Path,
    overrides: list[str],
    noise_in_meta: bool = False,
    recordings: tuple | None = None,
) -> tuple[dict, float]:
    """The diagnosis of ``experiment``'s set (or of ``recordings``, its (meta, curves) made otherwise), written into
    ``folder`` (``noise_in_meta``: with its noise std in meta.yaml, as a lab that measured it writes it), and the
    seconds it took."""
    meta, curves = simulate(experiment) if recordings is None else recordings
    write_recordings(folder, replace(meta, noise_std=experiment.noise_std) if noise_in_meta else meta, curves)
    with initialize_config_dir(config_dir=str(ROOT / "configs"), version_base="1.3"):
        cfg = compose(config_name="train", overrides=[f"data.path={folder}", *overrides])
    started = time.perf_counter()
    return run(typed(cfg), folder / "run", progress=lambda line: None).diagnosis, time.perf_counter() - started


def run_seeds(overrides: list[str], scratch: Path, count: int) -> None:
    """``count`` nulls and as many sets with ``SEEDED_TERM`` in the ``SEEDED`` setting, one seed each, diagnosed and
    tallied: how often noise alone is taken for a term or for unexplained structure, how often the term is named,
    another named in its place, or nothing; how often K's 95% interval covers the truth, and the term's strength
    interval where it is named; and the block inflation the nulls were judged under against the one the noise has."""
    ((term, params),) = SEEDED_TERM.items()
    truth = model_inflation(1.0 - SEEDED["noise_white_share"], SEEDED["noise_correlation"], 50)
    print(f"\nseeds: {count} nulls and {count} sets with {term} {params} in the bench-sets' p01/p07 setting")
    alarms, named, strong, other, nothing, inflations = 0, 0, 0, 0, 0, []
    covered = {"null": 0, "term": 0}  # K's interval holds the truth
    (strength, value), held = next(iter(params.items())), 0  # the term's named strength interval holds the truth
    for seed in range(count):
        outcome = {}
        for label, effects in (("null", {}), ("term", SEEDED_TERM)):
            experiment = Experiment(seed=seed, effects=effects, **SEEDED)
            d, _ = diagnose(experiment, scratch / f"{label}{seed}", overrides, noise_in_meta=True)
            outcome[label] = said(d)
            covered[label] += holds(d["permeability"]["corrected_interval"], experiment.permeability)
            if label == "null":
                alarms += d["mismatch"]["detected"] or bool(d["left_out"])
                inflations.append(d["noise"]["inflation"])
            else:
                terms = {e["term"]: e["confidence"] for e in d["left_out"]}
                named += term in terms
                held += any(e["term"] == term and holds(e["param_interval"][strength], value) for e in d["left_out"])
                strong += terms.get(term) == "strong"
                other += bool(set(terms) - {term})
                nothing += not terms
        print(f"seed {seed:3d}: null {outcome['null']:<40s} {term}: {outcome['term']}", flush=True)
    low, middle, high = np.quantile(inflations, [0.05, 0.5, 0.95])
    print(f"false alarms on the nulls: {alarms}/{count} (the structure test's stated rate: 1%)")
    print(
        f"{term} named {named}/{count} ({strong} strong); another term named {other}/{count}; nothing {nothing}/{count}"
    )
    print(
        f"K's 95% interval covers the truth on {covered['null']}/{count} nulls and {covered['term']}/{count} sets with "
        f"{term}; its {strength}'s on {held} of the {named} that name it"
    )
    print(
        f"block inflation the nulls' diagnoses used: median {middle:.1f} (5–95%: {low:.1f}–{high:.1f}), "
        f"against {truth:.1f} of the noise drawn"
    )


REAL_NOISE = {  # setting: (its experiment, the terms concealed beside the nulls, the noise std in meta.yaml)
    "soft cantilever": (SOFT, {}, False),
    "p07's, 0.3 µm of baseline": (SEEDED, SEEDED_TERM, True),
    "p04's and p06's, contacts estimated": (ESTIMATED_REAL, {"solid_relaxation": {"g": 0.2, "tau": 0.1}}, True),
}


# The shared bench-sets' families drawn again (``--suite families``): each shared set's setting and kind of noise (the
# simulator's AR(1) or white where the set has it, windows of real records where it has them, the materials in turn
# over the seeds), its concealed term at half, once and twice its strength, at other seeds, graded by the shared
# README's rules (``bench_sets.grade``). What the judged sets of these families will vary, and what the twelve sets
# alone cannot show. p12's adhesion is outside the simulator's effects: not drawn.
@dataclass(frozen=True)
class Family:
    setting: dict  # the family's ``Experiment``, from its shared set's truth.yaml
    materials: tuple[str, ...] = ()  # the real records' (``bench.real_noise``), in turn; none: the simulator's noise
    effects: tuple[dict, ...] = ({},)  # each drawn at every seed; {}: a null
    k_tol: float = 0.05  # K's tolerance, as the shared set's truth.yaml grades it


def _sizes(term: str, name: str, values: tuple[float, ...], **others: float) -> tuple[dict, ...]:
    return tuple({term: {name: value, **others}} for value in values)


SOFT_ESTIMATED = {  # p03's and p05's soft cantilever, contacts estimated under a tilted, offset baseline
    "probe_radius": 5e-6,
    "spring_constant": 0.09,
    "sample_thickness": 8e-5,
    "permeability": 6e-16,
    "effective_modulus": 2e3,
    "base_speeds": (3e-6, 9e-6, 27e-6),
    "samples": 1500,
    "z_start": -1.2e-6,
    "z_end": 0.85e-6,
    "noise_std": 1.3e-11,
    "contact_point": "estimate",
    "contact_error": 1e-7,
    "tilt": 4e-5,
    "baseline_offset": 4e-11,
}
HOLDS = {  # p10's and p11's ramp-and-holds, one a speed, white noise; their 3000 samples a curve are 1.0–2.7 kHz
    **{key: value for key, value in SEEDED.items() if key not in ("noise_correlation", "noise_white_share")},
    "base_speeds": (),
    "sample_rate": 2000.0,
}
FAMILIES = {
    "p01_null_ar_meta_noise": Family(SEEDED),
    "p02_null_estimate_offsets": Family(
        {**ESTIMATED_REAL, "z_start": -1.5e-6, "noise_std": 2.5e-10, "tilt": 2e-4, "baseline_offset": 4e-10}
    ),
    "p03_null_real_paam_noise": Family(
        {**SOFT_ESTIMATED, "base_speeds": (4e-6, 12e-6), "z_end": 0.75e-6}, ("PAAm",), k_tol=0.15
    ),
    "p04_null_real_correlated_noise": Family(ESTIMATED_REAL, ("agarose", "cells")),
    "p05_visc_soft_real_noise": Family(
        SOFT_ESTIMATED, ("PAAm",), _sizes("solid_viscosity", "gamma", (5.0, 10.0, 20.0))
    ),
    "p06_relax_real_correlated_noise": Family(
        ESTIMATED_REAL, ("agarose", "cells"), _sizes("solid_relaxation", "g", (0.1, 0.2, 0.4), tau=0.1)
    ),
    "p07_pore_ar_short_baseline": Family(SEEDED, effects=_sizes("pore_pressure_relaxation", "M", (1e5, 5e4, 2.5e4))),
    "p08_drag_estimate": Family(
        {**SEEDED, "z_start": -1.2e-6, "contact_point": "estimate", "contact_error": 1e-7, "tilt": 2e-4},
        effects=_sizes("cantilever_drag", "b", (5e-5, 1e-4, 2e-4)),
    ),
    "p09_visc_kperm_pair": Family(
        {**SEEDED, "noise_correlation": math.exp(-1.0 / 10.0), "noise_white_share": 0.5},
        effects=tuple(
            {"solid_viscosity": {"gamma": gamma}, "strain_dependent_permeability": {"m": m}}
            for gamma, m in ((6.0, 1.25), (12.0, 2.5), (24.0, 5.0))
        ),
    ),
    "p10_power_law_holds": Family(
        {**HOLDS, "holds": (Hold(2.5e-6, 1.5, 2e-6), Hold(2.5e-6, 1.5, 2e-5))},
        effects=_sizes("power_law_rheology", "alpha", (0.04, 0.08, 0.16)),
    ),
    "p11_pore_holds_real_noise": Family(
        {
            **HOLDS,
            "holds": (Hold(2.5e-6, 1.0, 5e-6), Hold(2.5e-6, 1.0, 25e-6)),
            "z_start": -0.8e-6,
            "sample_rate": 1600.0,  # near its set's 1.8–2.7 kHz as the PAAm records (2895 samples at most) allow
            "noise_std": 2e-10,
            "contact_point": "estimate",
            "contact_error": 1e-7,
        },
        ("PAAm",),
        _sizes("pore_pressure_relaxation", "M", (4e4, 2e4, 1e4)),
    ),
}


def _paired(family: str, *terms: dict) -> Family:
    """``family``'s setting and noise with the ``terms`` ({term: its parameters}) concealed together."""
    return replace(FAMILIES[family], effects=({name: p for term in terms for name, p in term.items()},))


# Two terms at once in the families' settings (``--suite pairs``): the judged sets vary the combinations too, and the
# shared ones hold one pair (p09's). Each term at its family's size, or the size its setting shows clearly.
VISCOSITY, DRAG = {"solid_viscosity": {"gamma": 12.0}}, {"cantilever_drag": {"b": 1e-4}}
RELAXATION, PERMEABILITY = {"solid_relaxation": {"g": 0.2, "tau": 0.1}}, {"strain_dependent_permeability": {"m": 2.5}}
PAIRS = {
    "p09 viscosity + drag": _paired("p09_visc_kperm_pair", VISCOSITY, DRAG),
    "p09 relaxation + viscosity": _paired("p09_visc_kperm_pair", RELAXATION, VISCOSITY),
    "p07 pore + viscosity": _paired("p07_pore_ar_short_baseline", {"pore_pressure_relaxation": {"M": 5e4}}, VISCOSITY),
    "p07 pore + strain K": _paired(
        "p07_pore_ar_short_baseline", {"pore_pressure_relaxation": {"M": 5e4}}, PERMEABILITY
    ),
    "p10 power law + pore": _paired(
        "p10_power_law_holds", {"power_law_rheology": {"alpha": 0.08}}, {"pore_pressure_relaxation": {"M": 2e4}}
    ),
    "p10 relaxation + pore": _paired("p10_power_law_holds", RELAXATION, {"pore_pressure_relaxation": {"M": 2e4}}),
    "p11 pore + relaxation": _paired("p11_pore_holds_real_noise", {"pore_pressure_relaxation": {"M": 2e4}}, RELAXATION),
    "p06 relaxation + drag": _paired("p06_relax_real_correlated_noise", RELAXATION, DRAG),
    "p08 drag + strain K": _paired("p08_drag_estimate", DRAG, PERMEABILITY),
    "p01 strain K + relaxation": _paired("p01_null_ar_meta_noise", PERMEABILITY, RELAXATION),
}


def run_families(
    overrides: list[str],
    scratch: Path,
    count: int,
    only: list[str] | None = None,
    families: dict[str, Family] = FAMILIES,
    suite: str = "families",
) -> tuple[list[Graded], list[bool]]:
    """Each of ``families`` (whose name holds one of ``only``: all without it) at seeds 1 to ``count``, graded as
    the shared sets are, a line printed as each finishes (headed ``suite``), and whether K's 95% interval holds the
    truth in each; the families of real noise skipped (said in one line) without the public records."""
    chosen = {name: f for name, f in families.items() if not only or any(word in name for word in only)}
    records = noise_records() if any(f.materials for f in chosen.values()) else {}  # read only where one needs them
    rows, held = [], []
    for name, family in chosen.items():
        if family.materials and records is None:
            continue
        for seed in range(1, count + 1):
            for effects in family.effects:
                experiment = Experiment(seed=seed, effects=effects, **family.setting)
                material = family.materials[seed % len(family.materials)] if family.materials else None
                recordings = with_real_noise(experiment, records[material]) if material else None
                size = ", ".join(f"{p} {v:g}" for params in effects.values() for p, v in params.items()) or "null"
                label = f"{name} s{seed} {size}" + (f" ({material})" if material else "")
                folder = scratch / re.sub(r"[^A-Za-z0-9]+", "_", label)
                d, seconds = diagnose(experiment, folder, overrides, True, recordings)
                expect = {"kind": "terms", "terms": sorted(effects)} if effects else {"kind": "none"}
                truth = {"expect": {**expect, "k_tol": family.k_tol}, "K": experiment.permeability, "effects": effects}
                rows.append(graded(label, truth, d, seconds))
                held.append(holds(d["permeability"]["corrected_interval"], experiment.permeability))
                print(f"{suite}: {rows[-1].line()}{'' if held[-1] else ' [K interval misses the truth]'}", flush=True)
    return rows, held


def run_real_noise(overrides: list[str], scratch: Path, count: int) -> None:
    """``count`` nulls in each ``REAL_NOISE`` setting (and as many sets with its term, where it has one), the noise
    of each a window of real pre-contact records (``bench.real_noise``), the materials in turn: how often real noise
    is taken for a term or for unexplained structure, material by material, and how often the term is named."""
    records = noise_records()
    if records is None:
        return
    for label, (setting, effects, noise_in_meta) in REAL_NOISE.items():
        beside = f" and {count} sets with {effects}" if effects else ""
        print(f"\nreal noise, {label} setting: {count} nulls{beside}")
        alarms, named = {m: [] for m in records}, []
        for seed in range(count):
            material = list(records)[seed % len(records)]
            outcome = []
            for concealed in ({}, effects) if effects else ({},):
                experiment = Experiment(seed=seed, effects=concealed, **setting)
                recordings = with_real_noise(experiment, records[material])
                folder = scratch / re.sub(r"[^A-Za-z0-9]+", "_", f"{label}{seed}{bool(concealed)}")
                d, _ = diagnose(experiment, folder, overrides, noise_in_meta, recordings)
                outcome.append(said(d))
                if concealed:
                    named.append(sorted(e["term"] for e in d["left_out"]) == sorted(concealed))
                else:
                    alarms[material].append(d["mismatch"]["detected"] or bool(d["left_out"]))
            term = f" term: {outcome[1]}" if effects else ""
            print(f"seed {seed:3d} ({material}): null {outcome[0]:<40s}{term}", flush=True)
        rates = ", ".join(f"{m} {sum(a)}/{len(a)}" for m, a in alarms.items())
        print(f"false alarms on the nulls (a term named or a mismatch declared): {rates}")
        if effects:
            print(f"{' + '.join(effects)} named (alone, any confidence): {sum(named)}/{len(named)}")


def said(d: dict) -> str:
    """What diagnosis ``d`` named, with confidences, and whether it called the rest unexplained, in a few words."""
    named = " + ".join(f"{e['term']} ({e['confidence']})" for e in d["left_out"]) or "-"
    return f"{named} unexplained" if d["unexplained"] else named


def holds(interval: list[float | None], truth: float) -> bool:
    """Whether a reported interval (None: a side open) holds ``truth``."""
    low, high = interval
    return (low is None or low <= truth) and (high is None or truth <= high)


def proposed(d: dict) -> list[dict]:
    """The distinct next experiments a diagnosis proposes: its confounded groups' and its terms below strong."""
    proposals = [g["next_experiment"] for g in d["confounded"] if g.get("next_experiment")]
    proposals += [e["next_experiment"] for e in d["left_out"] if e.get("next_experiment")]
    return list({json.dumps([p["protocol"], p["repeats"]]): p for p in proposals}.values())


def closed(case: Case, experiment: Experiment, d: dict) -> bool:
    """The concealed terms named, each strong, with K within 5%."""
    named = sorted(e["term"] for e in d["left_out"])
    strong = all(e["confidence"] == "strong" for e in d["left_out"])
    k_error = abs(relative_error(d["permeability"]["corrected"], experiment.permeability))
    return named == sorted(case.effects) and strong and k_error <= 0.05


def loop_row(case: Case, experiment: Experiment, folder: Path, overrides: list[str]) -> tuple:
    """Before → what ptwin proposes, recorded from the same truth → ptwin again, for at most ``ROUNDS`` rounds."""
    before, seconds = diagnose(experiment, folder / "r0", overrides)
    after, first, holds, rounds = before, proposed(before), (), 0
    while rounds < ROUNDS and not closed(case, experiment, after) and proposed(after):
        holds += tuple(hold for proposal in proposed(after) for hold in Hold.proposed(proposal))
        rounds += 1
        after, more = diagnose(replace(experiment, holds=holds), folder / f"r{rounds}", overrides)
        seconds += more
    k_before = 100 * relative_error(before["permeability"]["corrected"], experiment.permeability)
    k_after = 100 * relative_error(after["permeability"]["corrected"], experiment.permeability)
    return (
        case.name,
        "; ".join(" ~ ".join(g["terms"]) for g in before["confounded"]) or "-",
        "; ".join(p["sentence"].split(":")[0] for p in first) or "none",
        " + ".join(f"{e['term']} ({e['confidence']})" for e in after["left_out"]) or "-",
        k_before,
        k_after,
        rounds,
        seconds,
        "right" if closed(case, experiment, after) else "WRONG",
    )


def print_loop(rows: list[tuple]) -> None:
    print(f"\nloop: confounded before → proposed experiments recorded, round after round (at most {ROUNDS}) → named")
    print(
        f"{'case':<28s} {'confounded before':<60s} {'first proposed':<70s} {'named after':<40s} {'K %':>7s} "
        f"{'→ K %':>7s} {'rounds':>6s} {'s':>6s}"
    )
    for case, before, first, after, k_before, k_after, rounds, seconds, right in rows:
        print(
            f"{case:<28s} {before:<60.60s} {first:<70.70s} {after:<40.40s} {k_before:7.2f} {k_after:7.2f} "
            f"{rounds:6d} {seconds:6.1f} {right}"
        )
    print(f"{sum(r[-1] == 'right' for r in rows)}/{len(rows)} loops right")


def _positive(text: str) -> int:
    """A count given on the command line: a whole number ≥ 1 (argparse says which option, and the value, where not)."""
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of at least 1")
    return int(text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    suites = [*SUITES, "bench-sets", "perturbed", "seeds", "real-noise", "families", "pairs", "all"]
    parser.add_argument("--suite", choices=suites, default="all")
    parser.add_argument(
        "--seeds",
        type=_positive,
        help="sets of each kind in the seeds and real-noise suites (30), seeds of the families and pairs (3)",
    )
    parser.add_argument("--seed", type=int, default=0, help="the noise seed of the four suites' sets (0: the tables)")
    parser.add_argument(
        "--samples", type=_positive, default=1000, help="samples per curve (where not set by rate or case)"
    )
    parser.add_argument("--pgd", default="default", help="PGD preset")
    parser.add_argument("--only", nargs="*", help="run only the cases whose name contains one of these")
    args = parser.parse_args()
    warnings.filterwarnings("ignore", category=RuntimeWarning)
    register()
    cache = os.environ.get("PTWIN_CACHE", str(ROOT / ".cache" / "ptwin"))
    # every run lands in a scratch folder, deleted after its row: figures would be drawn for nobody
    overrides = [f"pgd={args.pgd}", f"cache_dir={cache}", "figures=false"]
    for suite in SUITES if args.suite == "all" else [s for s in SUITES if s == args.suite]:
        cases = [c for c in SUITES[suite] if not args.only or any(word in c.name for word in args.only)]
        rows, named_on_nulls, alarms = [], [], []
        with tempfile.TemporaryDirectory() as scratch:
            for case in cases:
                setting = {"samples": args.samples, "seed": args.seed, **case.setting}
                experiment = Experiment(effects=case.effects, **setting)
                folder = Path(scratch) / re.sub(r"[^A-Za-z0-9]+", "_", case.name)
                if suite == "loop":
                    rows.append(loop_row(case, experiment, folder, overrides))
                    name, *_, after, _, _, rounds, seconds, right = rows[-1]
                    print(f"loop: {case.name}: {after} after {rounds} rounds ({right}, {seconds:.1f} s)", flush=True)
                    continue
                d, seconds = diagnose(experiment, folder, overrides, case.noise_in_meta)
                rows.append(row(case, experiment, d, seconds))
                if not case.effects:
                    named_on_nulls.append(bool(d["left_out"]))
                if case.noise_alone:
                    alarms.append(d["mismatch"]["detected"] or bool(d["left_out"]))
                print(f"{suite}: {case.name}: {rows[-1][2]} ({rows[-1][-1]}, {rows[-1][-2]:.1f} s)", flush=True)
        if suite == "loop":
            print_loop(rows)
        else:
            print_table(f"{suite} suite", rows)
            if alarms:
                print(
                    f"false alarms on the nulls whose residual is noise alone: {sum(alarms)}/{len(alarms)} (the "
                    f"structure test's stated rate: 1%); a term named on a null: {sum(named_on_nulls)}/"
                    f"{len(named_on_nulls)}"
                )
    if args.suite in ("bench-sets", "all"):
        with tempfile.TemporaryDirectory() as scratch:
            shared = run_sets(overrides, Path(scratch), args.only)
        if shared:
            print_sets(shared)
    if args.suite == "seeds":  # not in "all": ~60 diagnoses
        with tempfile.TemporaryDirectory() as scratch:
            run_seeds([*overrides, "diagnosis.design=false"], Path(scratch), args.seeds or 30)
    if args.suite == "real-noise":  # not in "all": ~150 diagnoses, and the public curves it reads
        with tempfile.TemporaryDirectory() as scratch:
            run_real_noise([*overrides, "diagnosis.design=false"], Path(scratch), args.seeds or 30)
    if args.suite in ("families", "pairs"):  # not in "all": 25 (10) diagnoses a seed, the public curves read
        families = FAMILIES if args.suite == "families" else PAIRS
        with tempfile.TemporaryDirectory() as scratch:
            drawn, held = run_families(
                [*overrides, "diagnosis.design=false"], Path(scratch), args.seeds or 3, args.only, families, args.suite
            )
        if drawn:  # none where every family asked for needs the public records and they are absent (said above)
            title = {"families": "the shared bench-sets' families drawn again", "pairs": "two terms at once"}
            print_sets(drawn, title[args.suite], "ptwin's simulator, real noise where the set has it")
            print(f"K's 95% interval holds the truth at {sum(held)}/{len(held)} sets (a side left open holds it)")
    if args.suite == "perturbed":  # not in "all": a robustness check of ~35 diagnoses
        with tempfile.TemporaryDirectory() as scratch:
            shaken = run_perturbed([*overrides, "diagnosis.design=false"], Path(scratch), args.only)
        if shaken:
            print_sets(shaken, "shared bench-sets, perturbed")


if __name__ == "__main__":
    main()
