"""Figures of a run, one per paper figure it reproduces plus the diagnosis's, as PNG."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from ptwin.fitting.split import Split  # noqa: E402
from ptwin.physics.terms import VOCABULARY  # noqa: E402

NANO, MICRO = 1e9, 1e6


def _curves(samples, index):
    """(curve id, base speed, sample indices of index in it) per curve."""
    for i, curve in enumerate(samples.curve_ids):
        mine = index[samples.curve[index] == i]
        yield curve, samples.base_speed[mine[0]].item() if mine.numel() else float("nan"), mine


def _per_speed(samples, index, series: dict, ylabel: str, title: str, residual=False, measured=True):
    """Series against depth per curve; ``residual``: minus the measured force."""
    figure, ax = plt.subplots(figsize=(7, 4.5))
    colours = plt.cm.viridis(np.linspace(0, 0.9, len(samples.curve_ids)))
    for (curve, _, mine), colour in zip(_curves(samples, index), colours):
        depth = samples.depth[mine].numpy() * MICRO
        force = samples.force[mine].numpy()
        if measured and not residual:
            ax.plot(depth, force * NANO, ".", ms=1.5, color=colour, alpha=0.4, label=f"{curve} measured")
        for (label, values), style in zip(series.items(), ("-", "--", ":")):
            y = (values[mine].numpy() - (force if residual else 0)) * NANO
            ax.plot(depth, y, style, color=colour, lw=1, label=f"{curve} {label}")
    ax.set_xlabel("depth w [µm]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=6, ncol=2)
    figure.tight_layout()
    return figure


def save_figures(output_dir: Path, samples, split, identification, twin, diagnosis, corrected_per_curve):
    """Write every figure as PNG into ``output_dir``; returns {name: figure} for TensorBoard.

    ``identification``: stages 1–2 (``base``, ``apparent``, ``viscous_per_curve``); ``twin``: the hybrid
    twin; ``corrected_per_curve``: K per curve of the corrected model, or None.
    """
    base, apparent = identification.base, identification.apparent
    with torch.no_grad():  # evaluated where the models live, plotted from the CPU
        base_force = base.model(samples).cpu()
        physics, correction = (force.cpu() for force in twin(samples))
        corrected = diagnosis.corrected.fit.model(samples).cpu() if diagnosis is not None else None
    samples = samples.to("cpu")
    split = Split(*(part.cpu() for part in (split.train, split.val, split.test)))
    index = torch.cat([split.train, split.val, split.test]).sort().values
    figures = {
        "fig3_curves_base_model": _per_speed(
            samples, index, {"elastic + Darcy": base_force}, "force [nN]", "Measured curves and the base model"
        ),
        "fig4_apparent_permeability_depth": _apparent_against_depth(samples, index, apparent),
        "fig5_permeability_speed": _permeability_against_speed(apparent, base, corrected_per_curve),
        "fig6_viscosity_per_speed": _viscous_per_speed(apparent, identification.viscous_per_curve),
        "fig7_hybrid_fit": _per_speed(
            samples, index, {"hybrid twin": physics + correction}, "force [nN]", "Measured curves and the hybrid twin"
        ),
        "fig8_error_vs_network": _error_against_network(samples, split, index, physics, correction),
        "fig9_residuals": _per_speed(
            samples,
            index,
            {"base": base_force, "hybrid": physics + correction},
            "residual [nN]",
            "Residuals of the base model and the hybrid twin",
            residual=True,
        ),
    }
    if diagnosis is not None:
        figures.update(_diagnosis_figures(samples, index, base_force, correction, corrected, diagnosis.chosen))
    for name, figure in figures.items():
        figure.savefig(output_dir / f"{name}.png", dpi=110)
        plt.close(figure)
    return figures


def _apparent_against_depth(samples, index, apparent):
    figure, ax = plt.subplots(figsize=(7, 4.5))
    permeability = apparent.permeability.cpu()
    for curve, _, mine in _curves(samples, index):
        ax.semilogy(samples.depth[mine].numpy() * MICRO, permeability[mine].numpy(), ".", ms=1.5, label=curve)
    ax.set_xlabel("depth w [µm]")
    ax.set_ylabel("apparent K [m²]")
    ax.set_title("Pointwise apparent permeability (Newton per sample)")
    ax.legend(markerscale=6)
    return figure


def _speeds(apparent) -> np.ndarray:
    return np.array([row["base_speed"] for row in apparent.plateau.values()])


def _permeability_against_speed(apparent, base, corrected_per_curve):
    figure, ax = plt.subplots(figsize=(6, 4))
    rows = list(apparent.plateau.values())
    speeds = _speeds(apparent)
    ax.errorbar(
        speeds * MICRO,
        [r["mean"] for r in rows],
        yerr=[r["std_error"] for r in rows],
        fmt="o",
        label="plateau K, base model",
    )
    if corrected_per_curve:
        ax.errorbar(
            speeds * MICRO,
            [f.permeability for f in corrected_per_curve.values()],
            yerr=[f.permeability_std for f in corrected_per_curve.values()],
            fmt="s",
            label="K per speed, corrected model",
        )
    ax.axhline(base.permeability, color="grey", ls="--", lw=1, label="global K, base model")
    ax.set_xscale("log")
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel("base speed [µm/s]")
    ax.set_ylabel("K [m²]")
    ax.set_title(f"K against speed: slope {apparent.slope:.2g} ± {apparent.slope_std:.1g} m²/decade")
    ax.legend(fontsize=7)
    figure.tight_layout()
    return figure


def _viscous_per_speed(apparent, fits):
    """Stage 2 per curve: the viscous term's parameter and K against speed."""
    term = next(iter(fits.values())).terms[0]
    parameter, description = next(iter(VOCABULARY[term].PARAMS.items()))
    speeds = _speeds(apparent)
    figure, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.8))
    fits = list(fits.values())
    ax1.errorbar(
        speeds * MICRO,
        [f.params[term][parameter] for f in fits],
        yerr=[f.param_std[term][parameter] for f in fits],
        fmt="o",
    )
    ax1.axhline(0, color="red", lw=0.8)
    ax1.set_ylabel(description.label(parameter))
    ax2.plot(speeds * MICRO, [f.permeability for f in fits], "o")
    ax2.set_ylabel("K [m²]")
    for ax in (ax1, ax2):
        ax.set_xscale("log")
        ax.set_xlabel("base speed [µm/s]")
    figure.suptitle(f"(K, {parameter}) per speed, Gauss–Newton with {term}")
    figure.tight_layout()
    return figure


def _error_against_network(samples, split, index, physics, correction):
    figure, ax = plt.subplots(figsize=(5, 5))
    error = samples.force - physics
    for name, part in (("train", split.train), ("val", split.val), ("test", split.test)):
        ax.plot(error[part].numpy() * NANO, correction[part].numpy() * NANO, ".", ms=1.5, label=name)
    lim = float(error[index].abs().max()) * NANO
    ax.plot([-lim, lim], [-lim, lim], "k-", lw=0.8)
    ax.set_xlabel("model error E = F − F_el − F_D [nN]")
    ax.set_ylabel("network output Y1 [nN]")
    ax.set_title("What the network learned")
    ax.legend(markerscale=6)
    return figure


def _residual_map(ax, samples, index, residual, title, bins=24):
    rows = []
    for _, _, mine in _curves(samples, index):
        depth = samples.depth[mine].numpy()
        edges = np.linspace(0, depth.max(), bins + 1)
        which = np.clip(np.digitize(depth, edges) - 1, 0, bins - 1)
        scaled = (residual[mine] / samples.noise_floor[mine]).numpy()
        rows.append([scaled[which == b].mean() if np.any(which == b) else np.nan for b in range(bins)])
    image = ax.imshow(np.array(rows), aspect="auto", cmap="RdBu_r", vmin=-10, vmax=10)
    ax.set_yticks(range(len(samples.curve_ids)), samples.curve_ids)
    ax.set_xlabel(f"depth bin (of {bins}, to the deepest point)")
    ax.set_title(title)
    return image


def _diagnosis_figures(samples, index, base_force, correction, corrected, chosen):
    figures = {}
    label = " + ".join(chosen) or "no term accepted"
    figures["diagnosis_curves"] = _per_speed(
        samples,
        index,
        {"base": base_force, "corrected": corrected},
        "residual [nN]",
        f"Residuals: base model and corrected ({label})",
        residual=True,
    )
    figure, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=True)
    _residual_map(axes[0], samples, index, base_force - samples.force, "base model")
    image = _residual_map(axes[1], samples, index, corrected - samples.force, f"corrected ({label})")
    figure.colorbar(image, ax=axes, label="mean residual / noise floor")
    figures["diagnosis_residual_map"] = figure
    figures["diagnosis_network_vs_named"] = _per_speed(
        samples,
        index,
        {"network Y1": correction, "named terms": corrected - base_force},
        "force [nN]",
        "The hybrid network's learned error next to the named physics",
        measured=False,
    )
    return figures
