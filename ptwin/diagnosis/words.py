"""The diagnosis in words: the summary sentence, and numbers that are never ``nan``.

A quantity that could not be determined is said in words ("not determined") and is
``null`` in the JSON (``finite_or_none``); no sentence carries ``nan`` or ``inf``.
"""

from __future__ import annotations

import math

from ptwin.diagnosis.name import without_structure
from ptwin.physics.model import PLAUSIBLE_PERMEABILITY, fluid_off

HINTS = "; "  # between the differing terms' hints in a confounded group's 'tell_apart'

MICRO = 1e6
MATERIAL = 0.02  # a relative difference in K worth saying that K is not fixed
NO_FLUID = f"at the field's {PLAUSIBLE_PERMEABILITY[1]:.0e} m² limit or beyond"  # where K leaves no fluid force
UNRESOLVED = 2.0  # a validation RMS (× the noise std) worth a sentence where no structure is found


def finite_or_none(value):
    """``value`` with every non-finite float (at any depth of dicts and lists) replaced by None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: finite_or_none(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [finite_or_none(item) for item in value]
    return value


def number(value: float | None, spec: str, missing: str = "not determined") -> str:
    """``value`` formatted by ``spec``, or ``missing`` if it is None or not finite."""
    return format(value, spec) if value is not None and math.isfinite(value) else missing


def one_sided(interval) -> bool:
    """The data close one side of this 95% interval and not the other: a bound, no value."""
    low, high = interval
    return (low is None) != (high is None)


MISSES_DATA = "from a model that misses the data: no interval holds"


def bounded(value: float | None, interval, spec: str = ".3g", unit: str = "", misses_data: bool = False) -> str:
    """A fitted value as the data fix it. Both sides of its 95% interval closed: the value and the interval.
    One side open (a flat profile there): only the bound the data set, '< 3.1e-15 m²', since the fitted
    value is wherever the flat direction left the fit, not a measurement. Neither: 'not fixed by these data'.
    ``misses_data``: the value is what a model that leaves structure unexplained took, which no interval bounds."""
    if misses_data:
        return f"{number(value, spec)}{unit} ({MISSES_DATA})"
    low, high = interval
    if low is not None and high is not None:
        return f"{number(value, spec)}{unit} (95%: {low:{spec}} to {high:{spec}}{unit})"
    if high is not None:
        return f"< {high:{spec}}{unit} (95%; the data set no lower limit)"
    if low is not None:
        return f"> {low:{spec}}{unit} (95%; the data set no upper limit)"
    return "not fixed by these data"


def summarise(d, apparent, test) -> str:
    """One paragraph a person can read: where the base model misses, what (if anything) explains it, and K
    where the data bound it on one side only, or on none (where the findings do not say so with the models' K:
    real agarose at two speeds said nothing of K, its interval open both ways)."""
    interval, findings = d.permeability["corrected_interval"], _findings(d, apparent, test)
    bound = f" K {bounded(d.permeability['corrected'], interval, '.3g', ' m²')}." if one_sided(interval) else ""
    listed = _permeability_not_fixed(d)  # said in some findings, beside the K of each model
    if interval == [None, None] and not d.unexplained and not (listed and listed in findings):
        bound = f" K is {bounded(d.permeability['corrected'], interval)}."
    return findings + bound


def _findings(d, apparent, test) -> str:
    ratio = d.fit["base"]["val_rmse"] / d.noise_floor
    if not d.detected:
        # What the test found, not that the model is right: a misfit the test's null (the elastic law's own
        # noise, few baseline blocks) cannot tell from noise may still be several noise std.
        found = test.words(d.whiteness["base"])
        sentence = f"No structure in the base model's residual beyond what noise alone leaves ({found}; "
        sentence += f"validation RMS {ratio:.2f}× the noise std)."
        if ratio > UNRESOLVED:
            sentence += (
                " A misfit that large which the test cannot call structure is one these recordings cannot tell from "
                "what their noise could leave: the test rests on a few baseline blocks and on the noise of the one "
                "curve the elastic law is read off; longer baselines and a longer reference curve would sharpen it."
            ) + _learned_by_twin(d, ratio)
        return sentence + _permeability_not_fixed(d) + _to_tell_apart(d.confounded)
    sentence = _where(d, ratio, test) + _trend(apparent)
    entries = d.left_out
    names = " and ".join(entry["term"] for entry in entries)
    after = f"{d.fit['corrected']['val_rmse'] / d.noise_floor:.2f}× the noise std"
    if d.unexplained:
        kept = "the hybrid network's correction is kept, and " if d.fit["hybrid"]["val_rmse"] is not None else ""
        k = permeability_words(d.permeability["corrected"])
        part = "No term of the vocabulary explains the residual: "
        shaped = _without_structure(d, test)
        if shaped and not entries:
            part = (
                f"{' or '.join(shaped)} would leave no structure in it, but the selection rules keep none of them "
                "(see why each was pruned), so no term of the vocabulary explains it: "
            )
        if entries:
            part = (
                f"{names} {'take' if len(entries) > 1 else 'takes'} part of it (weak: the validation RMS falls "
                f"to {after}), but no term of the vocabulary explains what is left: "
            )
        missed = f"{part}{kept}K ({k}) comes from a model that misses the data, so no interval is given."
        return sentence + missed + _slower_than_measured(d)
    if all(entry["confidence"] != "weak" for entry in entries):
        grades = ", ".join(entry["confidence"] for entry in entries)
        them = "them" if len(entries) > 1 else "it"
        return (
            sentence
            + f"The base model left out {names} (confidence {grades}): with {them} the validation RMS falls to {after}."
            + _to_make_strong(entries)
        )
    sentence += f"{names} would explain it (the validation RMS falls to {after}), but the evidence is weak"
    if d.confounded:
        rivals = " or ".join(_called(group["terms"][1]) for group in d.confounded)
        sentence += f": the data cannot tell {names} from {rivals}."
        return sentence + _permeability_not_fixed(d) + _to_tell_apart(d.confounded)
    return sentence + "; see each term's evidence."


def _slower_than_measured(d) -> str:
    """A sentence where the structure spans more recorded samples than the longest record the noise's correlation
    was read on (``NoiseModel.longest``): noise that wanders over the longer span would leave it too, which these
    recordings cannot rule out; '' where it spans no more. A record sees the noise at scales up to its own length, and
    real cell noise wanders over the contact: in p07's setting (0.3 µm of baseline) with the public cells' records,
    baselines of at most 115 samples read it white (κ² 1.0) and 8 of 10 nulls read "unexplained" (one at whiteness
    18.1 against 8.0, over 1346 samples of its slowest curve). The same slow structure could be a model's miss, and no
    rule read off the residual alone tells the two apart (README, ``--suite real-noise``)."""
    if not d.where:
        return ""
    widest = max(d.where, key=lambda m: m.span)
    longest = d.noise.longest
    if widest.span <= longest:
        return ""
    read = f"on records of at most {longest} samples" if longest else "on no record of it"
    return (
        f" The noise's correlation was read {read}, and the structure spans {widest.span} samples of "
        f"{widest.curve}: noise that wanders over spans longer than it was read on (real cell noise does) would "
        f"leave such structure too, and these recordings cannot tell the two apart; baselines of {widest.span} "
        "samples a curve would."
    )


def _without_structure(d, test, most: int = 3) -> list[str]:
    """The smallest subsets of terms (at most ``most``, the least BIC first) whose physical fits leave no structure
    the test sees, where the selection rules kept none: what the residual's shape points to and the rules could
    not prove (on bench-set p03 with a solid relaxation of 64× the noise added, its fit left whiteness 1.3 against
    6.6 and took 14 units of χ² off the validation samples where noise and model error give up to 21; the summary
    had said no term explains the residual)."""
    return [" + ".join(c.terms) for c in without_structure(d.candidates, test)[:most]]


def _to_make_strong(entries: list[dict]) -> str:
    """' To make X strong, record …' for each named term that carries a proposal; '' otherwise."""
    return "".join(
        f" To make {e['term']} strong, record {e['next_experiment']['sentence']}."
        for e in entries
        if e.get("next_experiment")
    )


def _learned_by_twin(d, ratio: float) -> str:
    """Where no structure is found under a large misfit (``UNRESOLVED``), what the hybrid twin predicts, where it
    learned most of it (more than half the base model's mean square over the noise's): every K said then rests on
    one of the models fitted being right. A viscosity and a strain-dependent K at half bench-set p09's sizes, AR(1)
    noise read κ² 44 off 460 baseline samples (the noise's 15.6): the base model 2.81× the noise std, the twin
    1.64×, and K's 95% interval [2.15e-16, 2.30e-16] m² for 3e-16."""
    twin = d.fit.get("hybrid", {}).get("val_rmse")
    if twin is None:
        return ""
    twin_ratio = twin / d.noise_floor
    if ratio**2 - twin_ratio**2 <= (ratio**2 - 1.0) / 2:
        return ""
    return (
        f" The hybrid twin predicts the validation samples at {twin_ratio:.2f}× the noise std: its network "
        "learned what the base model misses, which may be physics none of the models fitted has, so every K here "
        "holds only if one of them is right."
    )


def _permeability_not_fixed(d) -> str:
    """' K is not fixed by these data: …' when the candidates that explain the data equally well give K
    values more than ``MATERIAL`` apart; '' otherwise."""
    ks = {name: k for group in d.confounded for name, k in group["permeability"].items() if k is not None}
    finite = [k for k in ks.values() if math.isfinite(k) and k > 0]
    if len(finite) < 2 or max(finite) / min(finite) - 1 <= MATERIAL:
        return ""
    listing = ", ".join(_permeability_with(k, _called(name)) for name, k in ks.items())
    low, high = d.permeability["corrected_interval"]
    covers = "" if low is None or high is None else f"; its 95% interval [{low:.3g}, {high:.3g}] m² covers them"
    return f" K is not fixed by these data: {listing}{covers}."


def permeability_words(k: float | None, spec: str = ".3g") -> str:
    """'2.7e-15 m²', or the limit a K without fluid force sits at."""
    return f"{NO_FLUID}: no fluid force" if k is not None and fluid_off(k) else f"{number(k, spec)} m²"


def _permeability_with(k: float, name: str) -> str:
    """'2.7e-15 m² with solid_viscosity', or the limit a K without fluid force sits at."""
    if fluid_off(k):
        return f"K {NO_FLUID} with {name} (no fluid force: any larger K fits as well)"
    return f"{permeability_words(k)} with {name}"


def _called(name: str) -> str:
    return "the base model" if name == "base model" else name


def _to_tell_apart(groups: list[dict]) -> str:
    """' To tell them apart, record …', each recording once: groups share hints (real PAAm with a strain-dependent
    K confounded with a relaxation and with a power law read 'a deeper indent (…)' twice)."""
    tell = HINTS.join(dict.fromkeys(hint for group in groups for hint in _record(group) if hint))
    return f" To tell them apart, record {tell}." if tell else ""


def _record(group: dict) -> list[str]:
    """What to record to tell a confounded group apart: the proposed experiment, else each differing term's hint."""
    proposal = group.get("next_experiment")
    return [proposal["sentence"]] if proposal else group["tell_apart"].split(HINTS)


def _where(d, ratio: float, test) -> str:
    if not test.structured(d.whiteness["base"]):  # named by a term's own shape (``null.TermEvidence``)
        shaped = d.evidence[" + ".join(d.chosen)]
        what = "one term" if len(d.chosen) == 1 else "these terms together"
        return (
            f"The base model misses the curves by {ratio:.1f}× the noise std. The residual as a whole passes for "
            f"noise ({test.words(d.whiteness['base'])}), but not in the shape of {what}: {shaped.words()}. "
        )
    if not d.where:
        return (
            f"The base model misses the curves by {ratio:.1f}× the noise std, in structure rather than noise "
            f"({test.words(d.whiteness['base'])}). "
        )
    curves = ", ".join(m.curve for m in d.where)
    lo = min(m.depth_from for m in d.where) * MICRO
    hi = max(m.depth_to for m in d.where) * MICRO
    worst = max(m.rms_residual / m.noise_floor for m in d.where)
    verb = "disagrees" if len(d.where) == 1 else "disagree"
    return (
        f"{curves} {verb} with the base model between {lo:.2f} and {hi:.2f} µm, up to {worst:.1f}× the noise "
        f"std ({test.words(d.whiteness['base'])}). "
    )


def times_better(gain: float, needed: float = math.inf) -> str:
    """'1.38× better', or '1.79× worse' for a gain below 1 (a ratio of test RMSEs, without over with); short of the
    ``needed`` ratio a decision compares it with, it reads short of it (``short_of``)."""
    if gain >= 1:
        return f"{short_of(gain, needed, 2)}× better"
    return f"{1 / gain:.2f}× worse" if gain > 0 else "worse"


def short_of(value: float, limit: float, decimals: int) -> str:
    """``value`` with ``decimals`` decimals, or with as many more (up to 6) as it takes to read below ``limit`` where it
    is below it: a held-out gain of 9.96% read "improves the prediction by only 10% (needs 10%)", and its ratio
    "predicts 1.10× better" beside a rule that asked for 10% better and found it short."""
    if value >= limit:
        return f"{value:.{decimals}f}"
    for places in range(decimals, decimals + 7):
        shown = f"{value:.{places}f}"
        if float(shown) < limit:
            return shown
    return f"{math.floor(value * 10**places) / 10**places:.{places}f}"  # rounded, it reads the limit still


def _trend(apparent) -> str:
    """The trend of the plateau permeability with speed, where there is one to measure (and it was); a plateau
    whose K no fluid force fixes is a bound, no value, and is said as such."""
    if apparent is None:
        return ""
    bounds = [curve for curve, row in apparent.plateau.items() if row.get("unfixed")]
    beside = (
        f"; at {', '.join(bounds)} no fluid force fixes it: the force is at or below the elastic law, or K {NO_FLUID}"
        if bounds
        else ""
    )
    if not (math.isfinite(apparent.slope) and math.isfinite(apparent.slope_std)):
        # the reference's speed says nothing here: a set of two speeds read "fewer than two fitted speeds" (real PAAm)
        return (
            "The plateau permeability cannot be compared across speeds (fewer than two speeds besides the reference "
            f"curve's, whose approach is the elastic law, give a plateau K{beside}). "
        )
    return (
        f"The plateau permeability changes with speed by {apparent.slope:.2g} m² per decade "
        f"({number(apparent.slope_significance, '.1f')} standard errors{_scatter(apparent)}{beside}). "
    )


def _scatter(apparent) -> str:
    """How often the trend's standard errors arise with no trend, or why that is not known."""
    if apparent.slope_dof < 1:
        return ", of the plateaus' own noise: with two plateaus the scatter between curves is not measured"
    p = apparent.slope_p_value
    if not math.isfinite(p):
        return ""
    return (
        f"; as many or more with no trend: p = {p:.2g}" if p >= 1e-4 else "; as many or more with no trend: p < 0.0001"
    )
