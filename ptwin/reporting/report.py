"""The run's summary table (stdout) and its human-readable report (report.md)."""

from __future__ import annotations

from pathlib import Path

NANO = 1e9


def _k(value, std=None):
    return f"{value:.4g}" + (f" ± {std:.2g}" if std is not None else "")


def summary_rows(results: dict) -> list[tuple[str, str, str, str]]:
    stages = results["stages"]
    labels = {"elastic_darcy": "1 elastic + Darcy", "viscous": "2 + viscous (K, gamma)", "hybrid": "3 hybrid twin"}
    rows = []
    for key, label in labels.items():
        stage = stages[key]
        rows.append(
            (
                label,
                _k(stage["permeability"], stage.get("permeability_std")),
                f"{stage['val_rmse'] * NANO:.3f}",
                f"{stage['test_rmse'] * NANO:.3f}",
            )
        )
    return rows


def print_summary(results: dict, diagnosis: dict) -> None:
    rows = summary_rows(results)
    fit = diagnosis["fit"]["corrected"]
    permeability = diagnosis["permeability"]
    rows.append(
        (
            "diagnosis: corrected",
            _k(permeability["corrected"], permeability["corrected_std"]),
            f"{fit['val_rmse'] * NANO:.3f}",
            f"{fit['test_rmse'] * NANO:.3f}",
        )
    )
    print(f"{'stage':<26s} {'K [m²]':>24s} {'val RMSE nN':>12s} {'test RMSE nN':>13s}")
    for row in rows:
        print(f"{row[0]:<26s} {row[1]:>24s} {row[2]:>12s} {row[3]:>13s}")
    print(f"noise floor {results['noise_floor'] * NANO:.3f} nN")
    print("diagnosis:", diagnosis["mismatch"]["summary"])


def write_report(output_dir: Path, results: dict, payload: dict, diagnosis, figures: dict) -> None:
    """report.md: the diagnosis in sentences and tables, the figures embedded."""
    noise = payload["noise_floor"]
    lines = ["# ptwin report", "", f"Recordings: `{results['recordings']}`", "", "## Diagnosis", ""]
    lines += [payload["mismatch"]["summary"], ""]
    if payload["mismatch"]["where"]:
        lines += [
            "| curve | depth from [µm] | depth to [µm] | RMS residual [nN] | noise floor [nN] |",
            "|---|---|---|---|---|",
        ]
        for w in payload["mismatch"]["where"]:
            lines.append(
                f"| {w['curve']} | {w['depth_from'] * 1e6:.2f} | {w['depth_to'] * 1e6:.2f} | "
                f"{w['rms_residual'] * NANO:.3f} | {w['noise_floor'] * NANO:.3f} |"
            )
        lines.append("")
    for entry in payload["left_out"]:
        params = ", ".join(f"{k} = {v:.4g} ± {entry['param_std'][k]:.2g}" for k, v in entry["params"].items())
        lines += [
            f"**Left out: `{entry['term']}`** ({params}; test RMSE gain {entry['test_rmse_gain']:.2f}×).",
            entry["evidence"],
            "",
        ]
    for entry in payload["rejected"]:
        params = ", ".join(f"{k} = {v:.4g}" for k, v in entry["params"].items())
        lines += [f"Rejected: `{entry['term']}` ({params}): {entry['why']} — not physical, so not an explanation.", ""]
    for entry in payload.get("confounded", []):
        lines += [
            f"Confounded: {entry['terms'][0]} and {entry['terms'][1]} explain the data equally well; "
            f"to tell them apart: {entry['tell_apart']}.",
            "",
        ]
    if payload["unexplained"]:
        lines += [
            "**Unexplained**: structure remains that no term of the vocabulary explains; the hybrid network's "
            "correction is kept and no term is claimed.",
            "",
        ]
    if diagnosis is not None:
        lines += [*(f"- {note}" for note in diagnosis.notes), ""]
        lines += [
            "### Candidate fits (train split; K refitted with each)",
            "",
            "| terms | BIC | val RMS [nN] | whiteness | parameters | physical |",
            "|---|---|---|---|---|---|",
        ]
        for terms, c in diagnosis.candidates.items():
            params = "; ".join(f"{k} = {v:.3g}" for p in c.fit.params.values() for k, v in p.items())
            lines.append(
                f"| {' + '.join(terms) or 'base'} | {c.fit.bic:.1f} | {c.val_rmse * NANO:.3f} | {c.whiteness:.1f} | "
                f"{params} | {'yes' if c.fit.physical else '; '.join(c.fit.violations.values())} |"
            )
        lines.append("")
    p = payload["permeability"]
    lines += [
        "## Fit",
        "",
        f"Noise floor {noise * NANO:.3f} nN. Permeability: base {p['base']:.4g} m², corrected "
        f"{p['corrected']:.4g} ± {p['corrected_std']:.2g} m².",
        "",
        "| model | val RMSE [nN] | test RMSE [nN] | test / noise |",
        "|---|---|---|---|",
    ]
    for name, fit in payload["fit"].items():
        lines.append(
            f"| {name} | {fit['val_rmse'] * NANO:.3f} | {fit['test_rmse'] * NANO:.3f} | "
            f"{fit['test_rmse'] / noise:.2f} |"
        )
    lines += [
        "",
        "## Identification chain",
        "",
        "| stage | K [m²] | val RMSE [nN] | test RMSE [nN] |",
        "|---|---|---|---|",
    ]
    lines += [f"| {' | '.join(row)} |" for row in summary_rows(results)]
    lines += ["", "## Figures", ""]
    lines += [f"![{name}]({name}.png)" for name in figures]
    (output_dir / "report.md").write_text("\n".join(lines) + "\n")
