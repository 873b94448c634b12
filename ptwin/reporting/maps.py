"""A force map's outputs: ``spots.csv``, ``map_summary.json``, the maps as PNG (K, each spot's verdict,
the base model's RMS over the noise) and ``report.md`` that shows them."""

from __future__ import annotations

import json
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from ptwin.diagnosis.spatial import FAILED, failure_reasons, grid, listed, verdict  # noqa: E402
from ptwin.reporting.figures import tight  # noqa: E402

MICRO = 1e6
NOT_DIAGNOSED = "spot not diagnosed"
LISTED = 12  # spots named in a line of the report; spots.csv has every one


def write_map_outputs(output_dir: Path, table: pd.DataFrame, summary: dict, figures: bool) -> None:
    """Everything a map run leaves beside its per-spot results; ``figures``: the maps as PNG too."""
    table.to_csv(output_dir / "spots.csv", index=False, float_format="%.9g")
    (output_dir / "map_summary.json").write_text(json.dumps(summary, indent=2))
    drawn = _maps(table) if figures and summary["diagnosed"] else {}  # no spot diagnosed: blank maps say nothing
    for name, figure in drawn.items():
        figure.savefig(output_dir / f"{name}.png", dpi=110)
        plt.close(figure)
    (output_dir / "report.md").write_text(_report(table, summary, list(drawn)))


def _maps(table: pd.DataFrame) -> dict:
    """The map's figures by file name: K, each spot's verdict, the base model's RMS over the noise."""
    return {
        "map_permeability": _map(
            table,
            np.log10(table["permeability"].astype(float)),
            "log10 K [m²]",
            f"{NOT_DIAGNOSED}, or no fluid force left there",
        ),
        "map_verdict": _verdict_map(table),
        "map_base_rmse": _map(table, table["base_rmse_over_noise"].astype(float), "base model RMS / noise std"),
    }


def _layout(table: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, list[float] | None]:
    """(column, row) of each spot on the image and the image's extent in µm (None: spots without positions,
    laid out in reading order)."""
    place = grid(table)
    if place is None:
        side = math.ceil(math.sqrt(len(table)))
        index = np.arange(len(table))
        return index % side, index // side, None
    column, row = place
    x, y = table["x"].to_numpy() * MICRO, table["y"].to_numpy() * MICRO
    dx = (x.max() - x.min()) / max(column.max(), 1) or 1.0
    dy = (y.max() - y.min()) / max(row.max(), 1) or 1.0
    return column, row, [x.min() - dx / 2, x.max() + dx / 2, y.min() - dy / 2, y.max() + dy / 2]


def _axes(extent, title: str):
    figure, ax = plt.subplots(figsize=(5.5, 4.5))
    ax.set_title(title)
    ax.set_xlabel("x [µm]" if extent else "spot (reading order)")
    ax.set_ylabel("y [µm]" if extent else "")
    return figure, ax


def _map(table: pd.DataFrame, values: pd.Series, label: str, blank: str = NOT_DIAGNOSED):
    """``values`` of each spot on the map's grid; ``blank``: what a spot without a value is."""
    column, row, extent = _layout(table)
    image = np.full((row.max() + 1, column.max() + 1), np.nan)
    image[row, column] = values.to_numpy()
    figure, ax = _axes(extent, label)
    shown = ax.imshow(image, origin="lower", extent=extent, cmap="viridis", interpolation="nearest")
    figure.colorbar(shown, ax=ax, label=label)
    ax.text(0.01, -0.16, f"blank: {blank}", transform=ax.transAxes, fontsize=8)
    tight(figure)
    return figure


def _verdict_map(table: pd.DataFrame):
    column, row, extent = _layout(table)
    verdicts = table.apply(verdict, axis=1)
    names = sorted(set(verdicts), key=lambda v: (v == FAILED, v))
    image = np.full((row.max() + 1, column.max() + 1), np.nan)
    image[row, column] = verdicts.map({name: i for i, name in enumerate(names)}).to_numpy()
    colours = plt.cm.tab10(np.arange(len(names)) % 10)
    colours[[i for i, name in enumerate(names) if name == FAILED]] = (0.85, 0.85, 0.85, 1.0)
    figure, ax = _axes(extent, "verdict per spot")
    ax.imshow(
        image,
        origin="lower",
        extent=extent,
        cmap=matplotlib.colors.ListedColormap(colours),
        vmin=-0.5,
        vmax=len(names) - 0.5,
        interpolation="nearest",
    )
    handles = [matplotlib.patches.Patch(color=c, label=n) for c, n in zip(colours, names)]
    ax.legend(handles=handles, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=1)
    tight(figure)
    return figure


def _report(table: pd.DataFrame, summary: dict, figures: list[str]) -> str:
    k, e = summary["permeability"], summary["effective_modulus"]
    lines = ["# Force map", "", f"{summary['diagnosed']} of {summary['spots']} spots diagnosed.", ""]
    if k["median"] is not None:
        lines += [
            f"- K: median {k['median']:.3g} m², 68% of spots within {k['p16']:.3g}–{k['p84']:.3g} m²",
            f"- E*: median {e['median']:.3g} Pa, 68% of spots within {e['p16']:.3g}–{e['p84']:.3g} Pa",
            "",
        ]
    lines += ["## Verdicts", "", "| verdict | spots |", "|---|---|"]
    lines += [f"| {name} | {count} |" for name, count in summary["verdicts"].items()]
    lines += ["", *summary["sentences"], ""]
    blank = "No maps drawn: no spot was diagnosed." if not summary["diagnosed"] else "No maps drawn (`figures=false`)."
    lines += [f"![{name}]({name}.png)" for name in figures] or [blank]
    reasons = failure_reasons(table)
    if reasons:
        lines += ["", "## Spots not diagnosed", "", "| why | spots |", "|---|---|"]
        lines += [f"| {reason.replace('|', '/')} | {_listed(spots)} |" for reason, spots in reasons.items()]
    return "\n".join(lines) + "\n"


def _listed(spots: list[str]) -> str:
    """The spots, the first ``LISTED`` by name, with their count."""
    return f"{listed(spots, LISTED)} ({len(spots)})"
