"""``results.json``: every number of the identification chain, from the stages' typed results;
and the run's files (results.json, diagnosis.json, report.md) written together."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import torch

from ptwin.data.kinematics import CurveKinematics
from ptwin.data.noise import NoiseModel
from ptwin.diagnosis.diagnose import Diagnosis
from ptwin.diagnosis.words import finite_or_none
from ptwin.fitting.hybrid_training import HybridOutcome, HybridSettings, rmse_of
from ptwin.fitting.physics_fit import PhysicsFit, rmse
from ptwin.fitting.pointwise import ApparentPermeability
from ptwin.fitting.split import Split
from ptwin.physics.samples import Samples
from ptwin.reporting.report import NOT_PHYSICAL, write_report


def physics_stage(fit: PhysicsFit, samples: Samples, split: Split) -> dict:
    """K, the terms' parameters, their standard deviations and the held-out RMSE [N] of one physics fit."""
    reasons = fit.why_not_physical
    return {
        "permeability": fit.permeability,
        "permeability_std": fit.permeability_std,
        "params": fit.params,
        "param_std": fit.param_std,
        "val_rmse": rmse(fit.model, samples, split.val),
        "test_rmse": rmse(fit.model, samples, split.test),
        "note": f"{reasons}{NOT_PHYSICAL}" if reasons else "",
    }


def apparent_record(apparent: ApparentPermeability) -> dict:
    return {
        "plateau": apparent.plateau,
        "slope_per_decade": apparent.slope,
        "slope_std": apparent.slope_std,
        "slope_dof": apparent.slope_dof,
        "slope_p_value": apparent.slope_p_value,
    }


def per_curve_record(fits: dict[str, PhysicsFit], term: str) -> dict:
    """K and the parameters of ``term`` with their std, per curve."""
    return {
        curve: {
            "permeability": f.permeability,
            **f.params[term],
            **{f"{name}_std": std for name, std in f.param_std[term].items()},
        }
        for curve, f in fits.items()
    }


def noise_record(curves: list[CurveKinematics], pooled: NoiseModel) -> dict:
    """The noise model of every curve and of the set."""
    return {
        "set": pooled.as_dict(),
        "curves": {c.curve: c.noise.as_dict() for c in curves},
    }


def contact_record(curves: list[CurveKinematics], base: PhysicsFit) -> dict | None:
    """Estimated contacts: each curve's estimate, removed baseline and the base fit's refinement [m, N, N/m]:
    the reference curve's own, every other curve's relative to it (``ContactNuisance``)."""
    if all(c.baseline is None for c in curves):
        return None
    contact = base.model.contact
    refined = {**contact.values(), base.model.reference.curve: contact.reference.item()} if contact else {}
    return {c.curve: {**asdict(c.baseline), "refinement": refined.get(c.curve, 0.0)} for c in curves if c.baseline}


def hybrid_stage(outcome: HybridOutcome, samples: Samples, split: Split, settings: HybridSettings) -> dict:
    twin = outcome.twin
    record = {
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
        record["network_rms"] = twin.network(samples)[fitted].square().mean().sqrt().item()
    return record


def write_outputs(output_dir: Path, results: dict, diagnosis: Diagnosis, figures: dict) -> dict:
    """Write results.json, diagnosis.json and report.md; returns the diagnosis.json payload."""
    payload = diagnosis.to_json()
    text = json.dumps(payload, indent=2, allow_nan=False, default=float, ensure_ascii=False)
    (output_dir / "diagnosis.json").write_text(text)
    (output_dir / "results.json").write_text(json.dumps(finite_or_none(results), indent=2, default=float))
    write_report(output_dir, results, payload, diagnosis, figures)
    return payload
