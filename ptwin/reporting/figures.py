"""Figures of a run, one per paper figure it reproduces plus the diagnosis's, as PNG."""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from ptwin.checks import first_line  # noqa: E402
from ptwin.data.recordings import CREEP, HOLD  # noqa: E402
from ptwin.fitting.split import Split  # noqa: E402
from ptwin.physics.terms import VOCABULARY  # noqa: E402

NANO, MICRO = 1e9, 1e6
MAX_PANELS = 6  # of the holds-and-creeps figure


def tight(figure) -> None:
    """``figure.tight_layout()``, done once: it leaves a placeholder layout engine behind, for which
    ``savefig`` draws the whole figure once more without rendering (0.38 s of the demo's 6.15 s, means of
    three runs)."""
    figure.tight_layout()
    figure.set_layout_engine(None)


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


class _Decades(matplotlib.ticker.LogFormatterSciNotation):
    """matplotlib's log-axis labels (10⁻¹⁶, 2×10⁻¹⁶) in Unicode, not mathtext: a mathtext label is parsed, the first
    of a process after ~0.2 s building its grammar, and four of the demo's figures have a log axis (0.75 s against
    0.49 s for four such figures in a fresh process). A label of another form stays as matplotlib writes it."""

    def __call__(self, x, pos=None):
        label = super().__call__(x, pos)
        found = re.fullmatch(r"\$\\mathdefault\{(?:(.+)\\times)?(\d+)\^\{(-?\d+)\}\}\$", label)
        if found is None:
            return label
        factor, base, power = found.groups()
        return f"{factor + '×' if factor else ''}{base}{power.translate(_SUPERSCRIPT)}"


def _logarithmic(ax, which: str) -> None:
    """A log scale on the ``which`` ("x" or "y") axis of ``ax``, labelled by ``_Decades``: minor ticks only where no
    decade is in view (matplotlib's own labelled them beside a single decade too, and 2×10⁰ to 6×10⁰ ran into one
    another under the speeds of two curves)."""
    getattr(ax, f"set_{which}scale")("log")
    axis = getattr(ax, f"{which}axis")
    axis.set_major_formatter(_Decades())
    axis.set_minor_formatter(_Decades(labelOnlyBase=False, minor_thresholds=(0, 0.4)))


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
    tight(figure)
    return figure


def figure_file(output_dir: Path, name: str) -> Path:
    """Where figure ``name`` is written (report.md links it by that name)."""
    return output_dir / f"{name}.png"


def stage_figures(output_dir: Path, samples, split, identification, twin, rate=None, progress=print) -> dict:
    """The figures of stages 1–3, saved as PNG into ``output_dir``: the paper's 3, 4 and 6–9 and the rate effect.
    The diagnosis changes none of them, so a run draws them aside beside it. Returns {name: its PNG file}.

    ``identification``: stages 1–2 (``base``, ``apparent``, ``viscous_per_curve``); ``twin``: the hybrid twin;
    ``rate``: the rate effect before any model (``ptwin.data.evidence.RateEffect``), or None. A figure matplotlib
    cannot draw from these data is left out with one line saying so (here and in the functions below)."""
    base_force, physics, correction = _forces(samples, identification.base.model, twin)
    samples, split, index = _on_cpu(samples, split)
    apparent = identification.apparent
    builders = {
        "fig3_curves_base_model": lambda: _per_speed(
            samples, index, {"elastic + Darcy": base_force}, "force [nN]", "Measured curves and the base model"
        ),
        "fig4_apparent_permeability_depth": lambda: _apparent_against_depth(samples, index, apparent),
        "fig6_viscosity_per_speed": lambda: _viscous_per_speed(
            apparent, identification.viscous_per_curve, identification.viscous_term
        ),
        "fig7_hybrid_fit": lambda: _per_speed(
            samples, index, {"hybrid twin": physics + correction}, "force [nN]", "Measured curves and the hybrid twin"
        ),
        "fig8_error_vs_network": lambda: _error_against_network(samples, split, index, physics, correction),
        "fig9_residuals": lambda: _per_speed(
            samples,
            index,
            {"base": base_force, "hybrid": physics + correction},
            "residual [nN]",
            "Residuals of the base model and the hybrid twin",
            residual=True,
        ),
    }
    if rate is not None:
        builders["rate_effect"] = lambda: _rate_effect(rate)
    return _drawn(output_dir, builders, progress)


def diagnosis_figures(
    output_dir: Path, samples, split, identification, twin, chosen, corrected_model, corrected_per_curve, progress=print
) -> dict:
    """The figures of the corrected model (the terms ``chosen``, ``corrected_model`` their fitted model), saved as
    PNG into ``output_dir``: the paper's 5 (``corrected_per_curve``: K per curve of the corrected model, or None),
    the holds and creeps where there are any, and the diagnosis's residuals and its network against the named
    terms. Returns {name: its PNG file}."""
    base_force, _, correction = _forces(samples, identification.base.model, twin)
    with torch.no_grad():
        corrected = corrected_model(samples).cpu()
    samples, split, index = _on_cpu(samples, split)
    apparent, base = identification.apparent, identification.base
    builders = {"fig5_permeability_speed": lambda: _permeability_against_speed(apparent, base, corrected_per_curve)}
    if bool((samples.in_contact & ((samples.segment == HOLD) | (samples.segment == CREEP))).any()):
        series = {"base": base_force, "corrected": corrected}
        builders["holds_force_time"] = lambda: _holds(samples, series)
    builders.update(_diagnosis_figures(samples, index, base_force, correction, corrected, chosen))
    return _drawn(output_dir, builders, progress)


def proposal_figures(output_dir: Path, predictions, progress=print) -> dict:
    """The next experiments the diagnosis proposes (``Diagnosis.predictions``), a figure each, saved as PNG into
    ``output_dir``. Returns {name: its PNG file}."""
    builders = {
        f"next_experiment_{number}": lambda prediction=prediction: _proposal(prediction)
        for number, prediction in enumerate(predictions, start=1)
    }
    return _drawn(output_dir, builders, progress)


def in_paper_order(figures: dict) -> dict:
    """The paper's figures by their number, the others after them in the order they came."""
    return dict(sorted(figures.items(), key=_paper_number))


def _forces(samples, base_model, twin) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The base model's force, the twin's physics and its network's correction [N], evaluated where the models
    live and brought to the CPU to be plotted."""
    with torch.no_grad():
        physics, correction = (force.cpu() for force in twin(samples))
        return base_model(samples).cpu(), physics, correction


def _on_cpu(samples, split):
    """``samples`` and ``split`` on the CPU, and the index of every sample of the split in time order."""
    samples = samples.to("cpu")
    split = Split(*(part.cpu() for part in (split.train, split.val, split.test)))
    return samples, split, torch.cat([split.train, split.val, split.test]).sort().values


def _drawn(output_dir: Path, builders: dict, progress) -> dict[str, Path]:
    """Each builder's figure, saved as PNG into ``output_dir``: {name: its file}; one that matplotlib cannot draw is
    said in a line. The files, not the figures: the figures drawn aside came back pickled, 8.1 MB for the demo's,
    pickled in the children and unpickled in the run's own process (0.08 s there) for figures it only names."""
    figures = {}
    for name, build in builders.items():
        path = figure_file(output_dir, name)
        try:
            figure = build()
            figure.savefig(path, dpi=110)
        except ValueError as error:  # e.g. no positive finite value to put on a log axis
            progress(f"figure {name} not drawn: {first_line(error)}")
            plt.close("all")
            continue
        plt.close(figure)
        figures[name] = path
    return figures


def _paper_number(item: tuple[str, object]) -> tuple[int, int]:
    """A figure's place: the paper's by their number, the others after them (a stable sort keeps their order)."""
    number = re.match(r"fig(\d+)_", item[0])
    return (0, int(number[1])) if number else (1, 0)


def _rate_effect(rate):
    """F/F_ref at equal depth of each faster approach: flat for a multiplicative effect (a power law, or a
    Darcy force ∝ R³ of a sphere), and how far above 1 for each speed."""
    figure, ax = plt.subplots(figsize=(6.5, 4))
    colours = plt.cm.viridis(np.linspace(0, 0.9, len(rate.profiles)))
    for profile, colour in zip(rate.profiles, colours):
        label = f"{profile.curve} ({profile.speed_ratio:.3g}× the speed)"
        ax.plot(profile.depth * MICRO, profile.ratio, "o-", ms=3, color=colour, label=label)
    ax.axhline(1.0, color="grey", lw=0.8)
    ax.set_xlabel("depth w [µm]")
    ax.set_ylabel(f"F / F_{rate.reference} at equal depth")
    ax.set_title("Rate effect before any model")
    ax.legend(fontsize=7)
    tight(figure)
    return figure


def _holds(samples, series: dict):
    """Force against time since each hold (or creep) began, on a log axis where relaxation is read: measured,
    and each model; one panel a segment, at most ``MAX_PANELS``."""
    panels = []
    for i in range(len(samples.curve_ids)):
        for code, kind in ((HOLD, "hold"), (CREEP, "creep at constant force")):
            mine = torch.nonzero((samples.curve == i) & (samples.segment == code) & samples.in_contact).squeeze(1)
            if mine.numel() > 1:
                panels.append((samples.curve_ids[i], kind, mine))
    panels = panels[:MAX_PANELS]
    figure, axes = plt.subplots(1, len(panels), figsize=(4.5 * len(panels), 3.8), squeeze=False)
    for ax, (curve, kind, mine) in zip(axes[0], panels):
        time = samples.time[mine].numpy()
        since = time - time[0] + 0.5 * float(np.median(np.diff(time)))  # the first sample, half a step in
        ax.plot(since, samples.force[mine].numpy() * NANO, ".", ms=1.5, color="grey", alpha=0.5, label="measured")
        for (label, values), style in zip(series.items(), ("-", "--")):
            ax.plot(since, values[mine].numpy() * NANO, style, lw=1.2, label=label)
        _logarithmic(ax, "x")
        ax.set_xlabel(f"time since the {kind.split()[0]} began [s]")
        ax.set_title(f"{curve}: {kind}", fontsize=9)
    axes[0][0].set_ylabel("force [nN]")
    axes[0][0].legend(fontsize=7)
    figure.suptitle("Holds and creeps against time (log axis)")
    tight(figure)
    return figure


def _proposal(prediction):
    """What each confounded candidate would record under the proposed experiment."""
    figure, ax = plt.subplots(figsize=(7, 4.2))
    for name, force in zip(prediction.names, prediction.forces):
        ax.plot(prediction.time, force * NANO, lw=1.2, label=name)
    if prediction.protocol.hold:
        ax.axvspan(prediction.time[-1] - prediction.protocol.hold, prediction.time[-1], color="tab:blue", alpha=0.08)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("predicted force [nN]")
    ax.set_title(f"Next experiment: {prediction.protocol.words()}\nseparation {prediction.separation:.1f}× the noise")
    ax.legend(fontsize=8)
    tight(figure)
    return figure


def _apparent_against_depth(samples, index, apparent):
    figure, ax = plt.subplots(figsize=(7, 4.5))
    permeability = apparent.permeability.cpu()
    for curve, _, mine in _curves(samples, index):
        ax.plot(samples.depth[mine].numpy() * MICRO, permeability[mine].numpy(), ".", ms=1.5, label=curve)
    _logarithmic(ax, "y")
    ax.set_xlabel("depth w [µm]")
    ax.set_ylabel("apparent K [m²]")
    ax.set_title("Pointwise apparent permeability (Newton per sample)")
    ax.legend(markerscale=6)
    return figure


def _speed_axis(ax, speeds) -> None:
    """A log x axis of base speed [µm/s] ticked at the speeds measured (``speeds`` [µm/s]), each labelled as
    recorded: a reader looks for the curves, not for decades, and 2–80 µm/s had read one label, "10¹"."""
    ax.set_xscale("log")
    measured = sorted({float(speed) for speed in speeds if np.isfinite(speed) and speed > 0})
    ax.xaxis.set_major_locator(matplotlib.ticker.FixedLocator(measured))
    ax.xaxis.set_major_formatter(matplotlib.ticker.StrMethodFormatter("{x:g}"))
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel("base speed [µm/s]")


def _speeds(apparent, curves) -> np.ndarray:
    """Base speed [m/s] of each of ``curves``."""
    return np.array([apparent.plateau[curve]["base_speed"] for curve in curves])


def _permeability_against_speed(apparent, base, corrected_per_curve):
    figure, ax = plt.subplots(figsize=(6, 4))
    rows = [row for row in apparent.plateau.values() if np.isfinite(row["mean"])]
    ax.errorbar(
        [r["base_speed"] * MICRO for r in rows],
        [r["mean"] for r in rows],
        yerr=[r["std_error"] if np.isfinite(r["std_error"]) else 0.0 for r in rows],
        fmt="o",
        label="plateau K, base model",
    )
    if corrected_per_curve:
        ax.errorbar(
            _speeds(apparent, corrected_per_curve) * MICRO,
            [f.permeability for f in corrected_per_curve.values()],
            yerr=[f.permeability_std for f in corrected_per_curve.values()],
            fmt="s",
            label="K per speed, corrected model",
        )
    ax.axhline(base.permeability, color="grey", ls="--", lw=1, label="global K, base model")
    _speed_axis(ax, [row["base_speed"] * MICRO for row in apparent.plateau.values()])
    ax.set_ylabel("K [m²]")
    if np.isfinite(apparent.slope) and np.isfinite(apparent.slope_std):
        ax.set_title(f"K against speed: slope {apparent.slope:.2g} ± {apparent.slope_std:.1g} m²/decade")
    else:
        no_slope = "K against speed: no slope\n(fewer than two speeds whose plateau K a fluid force fixes)"
        ax.set_title(no_slope, fontsize=10)
    ax.legend(fontsize=7)
    tight(figure)
    return figure


def _viscous_per_speed(apparent, fits, term):
    """Stage 2 per curve: the viscous term's parameter and K against speed."""
    parameter = VOCABULARY[term].strength()
    description = VOCABULARY[term].PARAMS[parameter]
    speeds = _speeds(apparent, fits)
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
        _speed_axis(ax, speeds * MICRO)
    figure.suptitle(f"(K, {parameter}) per speed, Gauss–Newton with {term}")
    tight(figure)
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


def _diagnosis_figures(samples, index, base_force, correction, corrected, chosen) -> dict:
    """Builders of the diagnosis's figures."""
    label = " + ".join(chosen) or "no term accepted"

    def residual_map():
        figure, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=True)
        _residual_map(axes[0], samples, index, base_force - samples.force, "base model")
        image = _residual_map(axes[1], samples, index, corrected - samples.force, f"corrected ({label})")
        figure.colorbar(image, ax=axes, label="mean residual / noise std")
        return figure

    return {
        "diagnosis_curves": lambda: _per_speed(
            samples,
            index,
            {"base": base_force, "corrected": corrected},
            "residual [nN]",
            f"Residuals: base model and corrected ({label})",
            residual=True,
        ),
        "diagnosis_residual_map": residual_map,
        "diagnosis_network_vs_named": lambda: _per_speed(
            samples,
            index,
            {"network Y1": correction, "named terms": corrected - base_force},
            "force [nN]",
            "The hybrid network's learned error next to the named physics",
            measured=False,
        ),
    }
