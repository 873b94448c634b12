"""python train.py [overrides]: the ptwin chain on a recording set (default: the bundled demo).

1. reads and checks the recording set, summarises its kinematics per curve;
2. reuses (or builds once) the cached PGD basis of the ``pgd`` preset;
3. stage 1 (paper §5.1): the global K and the pointwise apparent K(w) per speed;
4. stage 2 (§5.2): (K, gamma) with the viscous term, jointly and per speed;
5. stage 3 (§5.3): the hybrid twin, K next to an MLP of the model error, by LM over a λ grid;
6. the diagnosis: where the base model misses, which physics it left out, the refit.

Everything lands in the run directory: results.json, diagnosis.json, report.md, PNG
figures, TensorBoard events, checkpoint.pt. Bad input ends the run with one line and
exit code 2.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import hydra
import torch
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf
from torch.utils.tensorboard import SummaryWriter
from tqdm import tqdm

from ptwin.data.recordings import RecordingError, RecordingSet, load_recordings
from ptwin.diagnosis.diagnose import DiagnosisSettings, diagnose
from ptwin.fitting import checkpoint
from ptwin.fitting.hybrid import ErrorNetwork, HybridTwin
from ptwin.fitting.hybrid_training import HybridSettings, rmse_of, train_hybrid
from ptwin.fitting.physics_fit import fit_physics, rmse
from ptwin.fitting.pointwise import apparent_permeability
from ptwin.fitting.split import Split, split_samples
from ptwin.pgd.basis import Basis
from ptwin.pgd.cache import cached_basis
from ptwin.pgd.config import PGDConfig
from ptwin.physics.elastic import ReferenceElasticLaw
from ptwin.physics.fluid_force import FluidForce
from ptwin.physics.kinematics import CurveKinematics, curve_kinematics
from ptwin.physics.model import ForceModel
from ptwin.physics.samples import Samples
from ptwin.reporting.figures import save_figures
from ptwin.reporting.report import print_summary, write_report
from ptwin.schema import register

register()


def per_curve_fits(make_model, samples, index, terms, iterations, free_terms=True, values=None):
    """One fit per curve on the samples of ``index`` in it: {curve: PhysicsFit}."""
    fits = {}
    for i, curve in enumerate(samples.curve_ids):
        model = make_model(terms, values)
        for term in model.terms.values():
            term.requires_grad_(free_terms)
        fits[curve] = fit_physics(model, samples, index[samples.curve[index] == i], iterations)
    return fits


@dataclass
class Setup:
    """What every stage needs, built from the config: data, basis, split and model factories."""

    recordings: RecordingSet
    reference: CurveKinematics  # the reference (slowest) curve: its F(w) is the elastic law
    basis: Basis
    samples: Samples
    split: Split
    make_model: Callable[..., ForceModel]  # (terms=(), values=None, permeability=cfg.permeability)
    make_twin: Callable[[float, float], HybridTwin]  # (permeability, force scale [N])


def prepare(cfg: DictConfig) -> Setup:
    """Load and check the recordings, print their kinematics, get the cached basis, split."""
    recordings = load_recordings(cfg.data.path)
    meta = recordings.meta
    curves = curve_kinematics(recordings, smoothing=cfg.data.smoothing)
    print(f"{'curve':>6s} {'speed µm/s':>10s} {'contact':>8s} {'max depth µm':>12s} {'noise nN':>8s} {'offset nN':>9s}")
    for c in curves:
        print(
            f"{c.curve:>6s} {c.base_speed * 1e6:10.3g} {int(c.in_contact.sum()):8d} {c.depth.max() * 1e6:12.3f} "
            f"{c.noise_floor * 1e9:8.3f} {c.baseline_offset * 1e9:9.3f}"
        )
    basis = Basis.load(cached_basis(PGDConfig.from_dict(OmegaConf.to_container(cfg.pgd, resolve=True)), cfg.cache_dir))
    reference = next(c for c in curves if c.curve == meta.reference_curve)
    samples = Samples.from_curves([c for c in curves if c is not reference]).to(cfg.device)
    rho, thickness = meta.probe_radius, meta.sample_thickness
    split = split_samples(samples, tuple(cfg.split.fractions), cfg.split.mode, cfg.split.held_out_curve, cfg.seed)

    def make_model(terms=(), values=None, permeability=cfg.permeability):
        fluid = FluidForce(basis, permeability, meta.fluid_viscosity)
        elastic = ReferenceElasticLaw(reference, rho, thickness, None, cfg.model.elastic_nodes, cfg.data.smoothing)
        model = ForceModel(elastic, fluid, rho, thickness, terms, values, cfg.model.self_consistent)
        return model.to(cfg.device)

    def make_twin(permeability, force_scale):
        m = cfg.model
        generator = torch.Generator().manual_seed(cfg.seed)
        network = ErrorNetwork(m.inputs, m.hidden, m.activation, samples, split.train, force_scale, generator)
        return HybridTwin(make_model(permeability=permeability), network.to(cfg.device))

    return Setup(recordings, reference, basis, samples, split, make_model, make_twin)


def train(cfg: DictConfig, output_dir: Path) -> dict:
    """Run the chain for ``cfg`` and leave its results in ``output_dir``."""
    started = time.perf_counter()
    torch.manual_seed(cfg.seed)
    output_dir.mkdir(parents=True, exist_ok=True)
    setup = prepare(cfg)
    recordings, basis, samples, split, make_model = (
        setup.recordings,
        setup.basis,
        setup.samples,
        setup.split,
        setup.make_model,
    )
    meta = recordings.meta
    rho, thickness = meta.probe_radius, meta.sample_thickness
    reference = setup.reference
    iterations = cfg.optim.physics_fit.iterations
    writer = SummaryWriter(output_dir / "tensorboard")
    results = {"recordings": str(recordings.path), "basis_hash": basis.config_hash, "stages": {}}

    def stage_record(name, fit, note=""):
        record = {
            "permeability": fit.permeability,
            "permeability_std": fit.permeability_std,
            "params": fit.params,
            "param_std": fit.param_std,
            "val_rmse": rmse(fit.model, samples, split.val),
            "test_rmse": rmse(fit.model, samples, split.test),
            "note": note,
        }
        results["stages"][name] = record
        return record

    print("stage 1: global K (elastic + Darcy) and the pointwise apparent K(w)")
    base = fit_physics(make_model(), samples, split.train, iterations)
    stage_record("elastic_darcy", base)
    fluid_in_law = base.model.fluid if cfg.model.self_consistent else None
    consistent_law = ReferenceElasticLaw(
        reference, rho, thickness, fluid_in_law, cfg.model.elastic_nodes, cfg.data.smoothing
    )
    apparent = apparent_permeability(
        consistent_law,
        base.model.fluid,
        samples,
        rho,
        thickness,
        base.permeability,
        cfg.optim.pointwise.iterations,
        cfg.optim.pointwise.plateau_from,
    )
    results["apparent_permeability"] = {
        "plateau": apparent.plateau,
        "slope_per_decade": apparent.slope,
        "slope_std": apparent.slope_std,
    }

    print("stage 2: Gauss–Newton on (K, gamma) with the viscous term, jointly and per speed")
    viscous = fit_physics(
        make_model(("solid_viscosity",), permeability=base.permeability), samples, split.train, iterations
    )
    gamma = viscous.params["solid_viscosity"]["gamma"]
    stage_record("viscous", viscous, "gamma < 0: non-physical, rejected as an explanation" if gamma < 0 else "")
    viscous_per_speed = per_curve_fits(make_model, samples, split.train, ("solid_viscosity",), iterations)
    results["viscous_per_speed"] = {
        curve: {
            "permeability": f.permeability,
            "gamma": f.params["solid_viscosity"]["gamma"],
            "gamma_std": f.param_std["solid_viscosity"]["gamma"],
        }
        for curve, f in viscous_per_speed.items()
    }

    print("stage 3: the hybrid twin (K learnable + MLP of the model error), LM over the λ grid")
    config = OmegaConf.to_container(cfg, resolve=True)
    ckpt_file = output_dir / "checkpoint.pt"
    resume = checkpoint.load_checkpoint(cfg.ckpt_path, config, basis.config_hash) if cfg.ckpt_path else None
    noise = samples.noise_floor[split.train].mean().item()

    def make_twin():
        return setup.make_twin(base.permeability, noise)

    hybrid_cfg = cfg.optim.hybrid
    settings = HybridSettings(**OmegaConf.to_container(hybrid_cfg, resolve=True))
    n_train = split.train.numel()

    bar = tqdm(total=len(settings.regularisations) * settings.iterations, desc="hybrid LM", unit="step")

    def on_step(lambda_index, regularisation, step, twin, solver):
        global_step = lambda_index * settings.iterations + step.iteration
        bar.update(global_step - bar.n)
        bar.set_postfix(λ=f"{regularisation:g}", cost=f"{step.cost:.4g}")
        groups = twin.parameter_groups()
        names = groups["physics"] + groups["network"]
        writer.add_scalar("loss/train", 2 * step.cost / n_train, global_step)
        writer.add_scalar("loss/val", (rmse_of(twin, samples, split.val) / noise) ** 2, global_step)
        writer.add_scalar("param/permeability", twin.physics.fluid.permeability.item(), global_step)
        writer.add_scalar("lambda", regularisation, global_step)
        writer.add_scalar("damping", step.damping, global_step)
        sizes = [p.numel() for n, p in twin.named_parameters() if n in names]
        for group, members in groups.items():
            gradient = torch.cat([g for g, n in zip(step.gradient.split(sizes), names) if n in members])
            writer.add_scalar(f"grad_norm/{group}", gradient.norm().item(), global_step)
            writer.add_scalar(f"lr/{group}", settings.learning_rate[group], global_step)

    def save(state):
        checkpoint.save_checkpoint(ckpt_file, state, config, basis.config_hash)

    outcome = train_hybrid(make_twin, samples, split.train, split.val, settings, on_step, save, resume)
    bar.close()
    twin = outcome.twin
    hybrid_record = {
        "permeability": twin.physics.fluid.permeability.item(),
        "regularisation": outcome.regularisation,
        "val_rmse_per_regularisation": dict(zip(map(str, settings.regularisations), outcome.val_rmse)),
        "lm_iterations": outcome.iterations,
        "newton_iterations": outcome.newton_iterations,
        "val_rmse": rmse_of(twin, samples, split.val),
        "test_rmse": rmse_of(twin, samples, split.test),  # the test set, touched once
        "network_parameters": sum(p.numel() for p in twin.network.parameters()),
    }
    with torch.no_grad():
        fitted = torch.cat([split.train, split.val, split.test])
        hybrid_record["network_rms"] = twin.network(samples)[fitted].square().mean().sqrt().item()
    results["stages"]["hybrid"] = hybrid_record
    results["noise_floor"] = noise

    diagnosis = None
    if cfg.diagnosis.enabled:
        dcfg = OmegaConf.to_container(cfg.diagnosis, resolve=True)
        dcfg.pop("enabled")
        diagnosis = diagnose(
            make_model, samples, split, twin, apparent, DiagnosisSettings(**dcfg, iterations=iterations), base_fit=base
        )
        payload = diagnosis.to_json()
    else:
        payload = provisional_diagnosis(results, noise)
    (output_dir / "diagnosis.json").write_text(
        json.dumps(payload, indent=2, allow_nan=False, default=float, ensure_ascii=False)
    )
    corrected_per_speed = None
    if diagnosis is not None and diagnosis.chosen:
        values = diagnosis.corrected.fit.params
        corrected_per_speed = per_curve_fits(
            make_model, samples, split.train, diagnosis.chosen, iterations, False, values
        )
    figures = save_figures(
        output_dir, samples, split, base, viscous_per_speed, apparent, twin, diagnosis, corrected_per_speed
    )
    for name, figure in figures.items():
        writer.add_figure(name, figure)
    results["seconds"] = time.perf_counter() - started
    writer.add_hparams(
        {
            "hidden": cfg.model.hidden,
            "activation": cfg.model.activation,
            "lambda": outcome.regularisation,
            "seed": cfg.seed,
        },
        {"hparam/val_rmse": hybrid_record["val_rmse"], "hparam/test_rmse": hybrid_record["test_rmse"]},
        run_name=".",
    )
    writer.close()
    (output_dir / "results.json").write_text(json.dumps(results, indent=2, default=float))
    write_report(output_dir, results, payload, diagnosis, figures)
    print_summary(results, payload)
    print(f"results in {output_dir} ({results['seconds']:.1f} s)")
    return {"results": results, "diagnosis": payload}


def provisional_diagnosis(results: dict, noise_floor: float) -> dict:
    """diagnosis.json from the identification stages alone (``diagnosis.enabled=false``)."""
    stages = results["stages"]
    base, viscous = stages["elastic_darcy"], stages["viscous"]
    gamma = viscous["params"]["solid_viscosity"]["gamma"]
    return {
        "format": "ptwin-diagnosis/1",
        "mismatch": {
            "detected": base["val_rmse"] > 1.5 * noise_floor,
            "summary": f"provisional (diagnosis disabled): base validation RMS {base['val_rmse'] / noise_floor:.2f}× "
            f"the noise floor",
            "where": [],
        },
        "left_out": [],
        "rejected": [{"term": "solid_viscosity", "params": {"gamma": gamma}, "why": "gamma < 0"}] if gamma < 0 else [],
        "unexplained": base["val_rmse"] > 1.5 * noise_floor,
        "permeability": {
            "base": base["permeability"],
            "corrected": base["permeability"],
            "corrected_std": base["permeability_std"],
        },
        "noise_floor": noise_floor,
        "fit": {
            name: {"val_rmse": stages[key]["val_rmse"], "test_rmse": stages[key]["test_rmse"]}
            for name, key in (("base", "elastic_darcy"), ("corrected", "elastic_darcy"), ("hybrid", "hybrid"))
        },
    }


@hydra.main(version_base="1.3", config_path="configs", config_name="train")
def main(cfg: DictConfig) -> None:
    try:
        train(cfg, Path(HydraConfig.get().runtime.output_dir))
    except (RecordingError, checkpoint.CheckpointError) as error:
        print(error, file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
