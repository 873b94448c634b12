"""What the spots of a force map say together: each spot's verdict, the grid the spots lie on, and
whether a named term holds over a connected region (evidence from several neighbouring spots) or only
at scattered spots (each as weak as one set's verdict). A spot counts towards a term's regions when it
names the term with moderate or strong confidence; weak namings (the data there cannot tell it from an
alternative) are counted apart."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import ndimage

from ptwin.diagnosis.words import finite_or_none

MIN_REGION = 3  # neighbouring spots (sharing an edge of the grid) that make a region
FAILED, NOTHING, UNEXPLAINED = "not diagnosed", "nothing named", "unexplained"


def verdict(row) -> str:
    """A spot's verdict in a few words: what was named (with its confidence), or why nothing was."""
    if row["status"] != "ok":
        return FAILED
    named = " + ".join(f"{term} ({grade})" for term, grade in named_terms(row).items())
    if row["unexplained"]:
        return f"{named} + {UNEXPLAINED}" if named else UNEXPLAINED
    return named or NOTHING


def named_terms(row) -> dict[str, str]:
    """{term: confidence} of what a diagnosed spot names (empty for any other spot)."""
    if row["status"] != "ok" or not row["left_out"]:
        return {}
    return dict(zip(row["left_out"].split(";"), row["confidence"].split(";")))


def grid(table: pd.DataFrame) -> tuple[np.ndarray, np.ndarray] | None:
    """Each spot's (column, row) index on the map's grid, from its position (ranks of the distinct x and y,
    to the nanometre); None when a spot has no position."""
    if table[["x", "y"]].isna().to_numpy().any():
        return None
    column = np.unique(np.round(table["x"].to_numpy() * 1e9), return_inverse=True)[1]
    row = np.unique(np.round(table["y"].to_numpy() * 1e9), return_inverse=True)[1]
    return column, row


def regions(named: np.ndarray, column: np.ndarray, row: np.ndarray) -> list[np.ndarray]:
    """The spots (indices into ``named``) of each connected group of spots where ``named`` holds, largest first."""
    image = np.zeros((row.max() + 1, column.max() + 1), dtype=bool)
    image[row[named], column[named]] = True
    labels, _ = ndimage.label(image)  # edge neighbours
    spot_labels = labels[row, column] * named
    groups = [np.flatnonzero(spot_labels == label) for label in np.unique(spot_labels[spot_labels > 0])]
    return sorted(groups, key=len, reverse=True)


def failure_reasons(table: pd.DataFrame) -> dict[str, list[str]]:
    """Why spots could not be diagnosed: {reason: its spots}, the most frequent first. A reason is a spot's
    status without the spot's own path before it, so that spots refused for one cause (a map recorded at one
    speed) share one reason instead of a line each."""
    reasons: dict[str, list[str]] = {}
    for spot, status in zip(table["spot"], table["status"]):
        if status != "ok":
            reasons.setdefault(status.split(f"{spot}: ", 1)[-1], []).append(spot)
    return dict(sorted(reasons.items(), key=lambda item: -len(item[1])))


def summarise_map(table: pd.DataFrame) -> dict:
    """``map_summary.json``: the spots' verdicts counted, K and E* over the diagnosed spots (median and the
    spread between the 16th and 84th percentiles; K over the spots that have one), and for each named term where
    it holds."""
    ok = table[table["status"] == "ok"]
    verdicts = table.apply(verdict, axis=1)
    summary = {
        "spots": len(table),
        "diagnosed": len(ok),
        "verdicts": verdicts.value_counts().to_dict(),
        "permeability": _spread(ok["permeability"]),
        "effective_modulus": _spread(ok["effective_modulus"]),
        "terms": {},
        "sentences": [],
    }
    reasons = failure_reasons(table)
    if reasons:
        reason, spots = next(iter(reasons.items()))
        failed = len(table) - len(ok)
        which = "every one" if len(spots) == failed else f"{len(spots)} of them"
        summary["sentences"].append(
            f"{failed} of {len(table)} spots could not be diagnosed ({which}: {reason.rstrip('.')}); spots.csv "
            "gives each one's reason."
        )
    without = int(ok["permeability"].isna().sum())
    if without:
        summary["sentences"].append(
            f"At {without} of {len(ok)} diagnosed spots the fit left no fluid force, so any larger K fits as well: "
            "they give no K (spots.csv gives the lower bound the data set, where they set one), and K's median and "
            "spread are over the other spots."
        )
    summary["sentences"] += _places(table)
    place = grid(table)
    terms = sorted({t for names in ok["left_out"] for t in names.split(";") if t})  # named at any confidence
    for term in terms:
        grades = table.apply(lambda row, t=term: named_terms(row).get(t), axis=1)
        named = grades.isin(["moderate", "strong"]).to_numpy()
        entry = {"spots": int(named.sum()), "weak_spots": int((grades == "weak").sum())}
        if place is None:
            entry["sentence"] = (
                f"{term} is named with moderate or strong confidence at {entry['spots']} of {len(ok)} diagnosed "
                f"spots (weak at {entry['weak_spots']} more); without every spot's position, whether they form a "
                "region is not known."
            )
        else:
            groups = regions(named, *place)
            inside = [g for g in groups if len(g) >= MIN_REGION]
            entry["regions"] = [_extent(table.iloc[g]) for g in inside]
            entry["scattered"] = int(named.sum()) - sum(len(g) for g in inside)
            entry["sentence"] = _region_sentence(term, entry, len(ok))
        summary["terms"][term] = entry
        summary["sentences"].append(entry["sentence"])
    return finite_or_none(summary)


def _places(table: pd.DataFrame) -> list[str]:
    """What the spots' positions leave the maps unable to show: some spots without one (the maps then lay every spot
    out in reading order), spots that share one (a map's cell shows one of them); in sentences."""
    said = []
    missing = table["spot"][table[["x", "y"]].isna().any(axis=1)].tolist()
    if 0 < len(missing) < len(table):
        said.append(
            f"{len(missing)} of {len(table)} spots have no position in their meta.yaml ({listed(missing)}): the maps "
            "lay every spot out in reading order."
        )
    place = grid(table)
    if place is not None:
        at: dict[tuple[int, int], list[str]] = {}
        for spot, column, row in zip(table["spot"], *place):
            at.setdefault((column, row), []).append(spot)
        shared = [spots for spots in at.values() if len(spots) > 1]
        if shared:
            said.append(
                f"{len(shared)} position(s) hold more than one spot ({listed([' and '.join(g) for g in shared])}): "
                "each map shows one spot of each."
            )
    return said


def listed(names: list[str], most: int = 3) -> str:
    """The first ``most`` of ``names``, and how many more."""
    more = f", and {len(names) - most} more" if len(names) > most else ""
    return ", ".join(names[:most]) + more


def _spread(values: pd.Series) -> dict:
    values = values.dropna()
    if values.empty:
        return {"median": None, "p16": None, "p84": None}
    return {"median": float(values.median()), "p16": float(values.quantile(0.16)), "p84": float(values.quantile(0.84))}


def _extent(spots: pd.DataFrame) -> dict:
    return {
        "spots": len(spots),
        "x": [float(spots["x"].min()), float(spots["x"].max())],
        "y": [float(spots["y"].min()), float(spots["y"].max())],
    }


def _region_sentence(term: str, entry: dict, diagnosed: int) -> str:
    sentence = f"{term} is named with moderate or strong confidence at {entry['spots']} of {diagnosed} diagnosed spots"
    if entry["regions"]:
        described = ", ".join(
            f"{r['spots']} spots over x {r['x'][0] * 1e6:.3g}–{r['x'][1] * 1e6:.3g} µm, "
            f"y {r['y'][0] * 1e6:.3g}–{r['y'][1] * 1e6:.3g} µm"
            for r in entry["regions"]
        )
        sentence += f": in {len(entry['regions'])} connected region(s) ({described})"
    if entry["scattered"]:
        sentence += (
            f"{';' if entry['regions'] else ':'} {entry['scattered']} at scattered spots (fewer than {MIN_REGION} "
            "neighbours together), weaker evidence than a region"
        )
    if entry["weak_spots"]:
        sentence += f"; with weak confidence at {entry['weak_spots']} more spots, which no region counts"
    return sentence + "."
