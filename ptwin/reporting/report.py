"""The run's summary table (stdout) and its human-readable report (report.md).

Every number goes through ``number``: a quantity that could not be determined is said
in words, never printed as nan or inf.
"""

from __future__ import annotations

from pathlib import Path

from ptwin.diagnosis.diagnose import Diagnosis
from ptwin.diagnosis.words import MISSES_DATA, bounded, number, one_sided, permeability_words
from ptwin.physics.model import PLAUSIBLE_PERMEABILITY, fluid_off

NANO = 1e9
LABELS = {"elastic_darcy": "1 elastic + Darcy", "viscous": "2 + viscous (K, gamma)", "hybrid": "3 hybrid twin"}
NOT_PHYSICAL = ": non-physical, rejected as an explanation"  # ends a stage's note after its violations (results.json)


def _k(value, std=None) -> str:
    """K [m²] ± its std, as far as the data fix it: a K without fluid force is the field's limit, and a std
    larger than K itself bounds nothing (the table has no room for the interval)."""
    if value is not None and fluid_off(value):
        return f"no fluid force: ≥ {PLAUSIBLE_PERMEABILITY[1]:.0e}"
    if std is not None and value is not None and std > value:
        return f"{number(value, '.4g')} (not fixed)"
    return number(value, ".4g") + (f" ± {number(std, '.2g')}" if std is not None else "")


def _nano(value) -> str:
    return number(None if value is None else value * NANO, ".3f")


def _stage_k(stage: dict) -> str:
    """A stage's K as its fit found it, without its curvature std (kept in results.json): that std is no interval
    where the stage's model misses the data or K's profile is flat (real PAAm: ± 6% beside "K is not fixed by
    these data"), and the interval the data support is the diagnosis's own row. A fit that is not physical says so."""
    value = stage["permeability"]
    if value is not None and fluid_off(value):
        return _k(value)
    reason = stage.get("note", "").removesuffix(NOT_PHYSICAL)
    return number(value, ".4g") + (f" ({reason}: not physical)" if reason else "")


def summary_rows(results: dict) -> list[tuple[str, str, str, str]]:
    rows = []
    for key, label in LABELS.items():
        stage = results["stages"].get(key)
        if stage is not None:
            rows.append((label, _stage_k(stage), _nano(stage["val_rmse"]), _nano(stage["test_rmse"])))
    return rows


def print_summary(results: dict, diagnosis: dict, progress=print, fitted: dict | None = None) -> None:
    """The identification chain and the diagnosis's K as a table, and its summary sentence. ``fitted``: K as the
    fits found it, which says where a K diagnosis.json leaves null sits (default: diagnosis.json's)."""
    rows = summary_rows(results)
    fit = diagnosis["fit"]["corrected"]
    permeability = diagnosis["permeability"]
    low, high = permeability["corrected_interval"]
    value = (fitted or permeability)["corrected"]
    corrected = _k(value, permeability["corrected_std"])
    if one_sided((low, high)):  # the bound is all the data say
        corrected = f"< {high:.4g}" if low is None else f"> {low:.4g}"
    elif permeability["corrected_std"] is None and low is not None:  # rivals or a held contact: the interval, no std
        corrected = f"{number(permeability['corrected'], '.3g')} [{low:.2g}, {high:.2g}]"
    elif low is None and value is not None and not fluid_off(value):  # no side closed, as report.md says it
        # (real PAAm, two speeds: "4.233e-16" here beside "corrected not fixed by these data" in report.md)
        unexplained = diagnosis.get("unexplained")
        corrected = (
            f"{number(value, '.4g')} (the model misses the data)" if unexplained else bounded(value, [None, None])
        )
    rows.append(("diagnosis: corrected", corrected, _nano(fit["val_rmse"]), _nano(fit["test_rmse"])))
    width = max(24, *(len(row[1]) for row in rows))
    progress(f"{'stage':<26s} {'K [m²]':>{width}s} {'val RMSE nN':>12s} {'test RMSE nN':>13s}")
    for row in rows:
        progress(f"{row[0]:<26s} {row[1]:>{width}s} {row[2]:>12s} {row[3]:>13s}")
    progress(f"noise floor {_nano(results['noise_floor'])} nN")
    progress(f"diagnosis: {diagnosis['mismatch']['summary']}")


def write_report(output_dir: Path, results: dict, payload: dict, diagnosis: Diagnosis, figures: dict) -> None:
    """report.md: the diagnosis in sentences and tables, the figures embedded."""
    lines = ["# ptwin report", "", f"Recordings: `{results['recordings']}`", "", "## Diagnosis", ""]
    lines += [payload["mismatch"]["summary"], ""]
    lines += _where(payload) + _left_out(payload) + _others(payload)
    lines += [*(f"- {note}" for note in payload["notes"]), ""]
    lines += _candidates(diagnosis)
    lines += _fit(payload, diagnosis.permeability) + _chain(results)
    none = "None drawn (`figures=false`, or none could be: the run's output says why)."
    drawn = [f"![{name}]({path.name})" for name, path in figures.items()] or [none]
    lines += ["## Figures", "", *drawn]
    (output_dir / "report.md").write_text("\n".join(lines) + "\n")


def _where(payload: dict) -> list[str]:
    if not payload["mismatch"]["where"]:
        return []
    lines = [
        "| curve | depth from [µm] | depth to [µm] | RMS residual [nN] | noise std [nN] |",
        "|---|---|---|---|---|",
    ]
    for w in payload["mismatch"]["where"]:
        lines.append(
            f"| {w['curve']} | {number(w['depth_from'] * 1e6, '.2f')} | {number(w['depth_to'] * 1e6, '.2f')} | "
            f"{_nano(w['rms_residual'])} | {_nano(w['noise_floor'])} |"
        )
    return [*lines, ""]


def _left_out(payload: dict) -> list[str]:
    lines = []
    for entry in payload["left_out"]:
        params = ", ".join(
            f"{k} {bounded(v, entry['param_interval'][k], '.4g', misses_data=payload['unexplained'])}"
            for k, v in entry["params"].items()
        )
        lines += [
            f"**Left out: `{entry['term']}`**, confidence **{entry['confidence']}** ({params}; test RMSE gain "
            f"{number(entry['test_rmse_gain'], '.2f')}×).",
            entry["evidence"],
            "",
        ]
    return lines


def _others(payload: dict) -> list[str]:
    lines = []
    for entry in payload["rejected"]:
        params = ", ".join(f"{k} = {number(v, '.4g')}" for k, v in entry["params"].items())
        lines += [f"Rejected: `{entry['term']}` ({params or 'no values'}): {entry['why']}.", ""]
    for entry in payload["confounded"]:
        lines += [
            f"Confounded: {entry['terms'][0]} and {entry['terms'][1]} explain the data equally well; "
            f"to tell them apart: {entry['tell_apart']}.",
            "",
        ]
    if payload["unexplained"]:
        named = " and ".join(f"`{entry['term']}`" for entry in payload["left_out"])
        verb = "takes" if len(payload["left_out"]) == 1 else "take"
        beyond = f" beyond what {named} {verb} (named, weak)" if named else ""
        said = ["the hybrid network's correction is kept"] * (payload["fit"]["hybrid"]["val_rmse"] is not None)
        said += ["no term is claimed"] * (not named)
        tail = f"; {' and '.join(said)}" if said else ""
        lines += [f"**Unexplained**: structure remains{beyond} that no term of the vocabulary explains{tail}.", ""]
    return lines


def _candidates(diagnosis) -> list[str]:
    lines = [
        "### Candidate fits (train split; K refitted with each; BIC under the noise model)",
        "",
        "| terms | BIC | val RMS [nN] | whiteness | parameters | state |",
        "|---|---|---|---|---|---|",
    ]
    for terms, c in diagnosis.candidates.items():
        name = " + ".join(terms) or "base"
        if c.fit is None:
            lines.append(f"| {name} | – | – | – | – | {c.state} |")
            continue
        params = "; ".join(f"{k} = {number(v, '.3g')}" for p in c.fit.params.values() for k, v in p.items())
        lines.append(
            f"| {name} | {number(c.fit.bic, '.1f')} | {_nano(c.val_rmse)} | {number(c.whiteness, '.1f')} | "
            f"{params} | {c.state} |"
        )
    return [*lines, ""]


def _fit(payload: dict, fitted: dict) -> list[str]:
    """The noise model, K and the fits' RMS. ``fitted``: K as the fits found it, whose words say where a K the
    payload leaves null sits (the field's limit, no fluid force)."""
    noise = payload["noise"]
    time = noise["correlation_time"]
    correlation = number(None if time is None else time * 1e3, ".2g")
    lines = [
        "## Fit",
        "",
        f"Noise: std {_nano(noise['std'])} nN, correlation time {correlation} ms, block-variance inflation "
        f"{number(noise['inflation'], '.2f')} (from the {noise['source']}); every statistic above uses it."
        + _drift(noise.get("drift")),
        "",
        f"Permeability: base {permeability_words(fitted['base'], '.4g')}, corrected {_corrected_k(payload, fitted)}.",
        "",
        "| model | val RMSE [nN] | test RMSE [nN] | test / noise std |",
        "|---|---|---|---|",
    ]
    for name, fit in payload["fit"].items():
        ratio = None if fit["test_rmse"] is None else fit["test_rmse"] / noise["std"]
        lines.append(f"| {name} | {_nano(fit['val_rmse'])} | {_nano(fit['test_rmse'])} | {number(ratio, '.2f')} |")
    return [*lines, ""]


def _drift(drift: dict | None) -> str:
    """The drift the baselines' slopes hold beyond the noise model, in a sentence ("" where none)."""
    if drift is None or not drift["share"]:
        return ""
    return (
        f" The baselines' slopes scatter about their line in the speed beyond it (χ² {drift['chi_square']:.1f} on "
        f"{drift['dof']} degrees of freedom): the tests of structure and of each term's shape add a drift of "
        f"{drift['share']:.2g} of its variance, correlated over {number(drift['correlation_time'] * 1e3, '.2g')} ms "
        "(the baselines' length)."
    )


def _corrected_k(payload: dict, fitted: dict) -> str:
    """The corrected K as the data fix it; none from a model that leaves the data unexplained (``fitted``: as
    its fit found it)."""
    p = payload["permeability"]
    if payload["unexplained"]:
        return f"{permeability_words(fitted['corrected'], '.4g')} ({MISSES_DATA})"
    return bounded(p["corrected"], p["corrected_interval"], ".4g", " m²")


def _chain(results: dict) -> list[str]:
    lines = ["## Identification chain", "", "| stage | K [m²] | val RMSE [nN] | test RMSE [nN] |", "|---|---|---|---|"]
    lines += [f"| {' | '.join(row)} |" for row in summary_rows(results)]
    lines += ["", "Each stage's K as its fit found it; how far the data fix K is the Fit section's interval above."]
    return [*lines, ""]
