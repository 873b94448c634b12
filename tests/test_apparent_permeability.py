"""Stage 1's plateau permeability per speed: a plateau with no fluid force to fix K is a bound, not a value."""

import math
from dataclasses import replace
from types import SimpleNamespace

import pytest
import torch

from ptwin.data.recordings import APPROACH
from ptwin.diagnosis.words import _trend
from ptwin.fitting.physics_fit import fit_physics
from ptwin.fitting.pointwise import _weighted_slope, apparent_permeability
from ptwin.pipeline.prepare import prepare
from tests.conftest import settings_for


@pytest.fixture(scope="module")
def fitted_set(default_set, coarse_cache):
    """A simulated set, prepared, and its base model fitted (shared by the tests that read its plateaus)."""
    settings = settings_for(f"data.path={default_set}", "pgd=coarse", f"cache_dir={coarse_cache}")
    prepared = prepare(settings, lambda _: None)
    return prepared, fit_physics(prepared.make_model(), prepared.samples, prepared.split.train)


def test_a_gel_without_fluid_force_has_its_plateaus_said_to_be_bounds(fitted_set):
    # Real PAAm (two spots at 15 µm/s beside one at 5): the plateau K of curves where no fluid force is left came
    # out near 0.1 m² and the summary read "the plateau permeability changes with speed by -0.12 m² per decade".
    # Here every curve's force is the elastic law alone (the model at K = 1e-7 m²): every plateau is a bound.
    prepared, base = fitted_set
    assert base.settled  # the fit these plateaus are read against ended at an optimum, not at its step cap
    with torch.no_grad():
        elastic = prepared.make_model((), None, 1e-7)(prepared.samples)
    apparent = apparent_permeability(base.model, replace(prepared.samples, force=elastic), base.permeability)
    assert all(row["unfixed"] and math.isnan(row["mean"]) for row in apparent.plateau.values())
    assert math.isnan(apparent.slope)
    sentence = _trend(apparent)
    assert sentence.startswith("The plateau permeability cannot be compared across speeds (fewer than two fitted")
    assert "no fluid force fixes it: the force is at or below the elastic law, or K at the field's" in sentence
    assert "nan" not in sentence
    fitted = apparent_permeability(base.model, prepared.samples, base.permeability)  # the gel as simulated
    assert not any(row["unfixed"] for row in fitted.plateau.values()) and math.isfinite(fitted.slope)


def test_a_curve_whose_approach_is_not_fitted_has_no_plateau_and_is_no_bound(fitted_set):
    # A JPK creep of a polymer gel (afmformats' test file), the set's one curve and so its reference: only its creep
    # is fitted (its approach is the elastic law). Its plateau row had no speed (figures 5 and 6 were not drawn:
    # "Data cannot be log-scaled") and the trend called it a bound "no fluid force fixes".
    prepared, base = fitted_set
    samples = prepared.samples
    first = (samples.curve == 0) & (samples.segment == APPROACH)
    unfitted = replace(samples, in_contact=samples.in_contact & ~first)
    apparent = apparent_permeability(base.model, unfitted, base.permeability)
    row = apparent.plateau[samples.curve_ids[0]]
    assert row["base_speed"] == samples.nominal_speed[first][0].item() > 0
    assert row["samples"] == 0 and math.isnan(row["mean"]) and not row["unfixed"]
    assert samples.curve_ids[0] not in _trend(apparent)


def test_a_bound_beside_fitted_plateaus_is_named_in_the_trend():
    rows = {
        "v1": {"unfixed": False, "mean": 2e-16},
        "v4": {"unfixed": False, "mean": 2.2e-16},
        "v16": {"unfixed": True, "mean": math.nan},
    }
    apparent = SimpleNamespace(plateau=rows, slope=2e-17, slope_std=1e-17, slope_significance=2.0)
    assert _trend(apparent) == (
        "The plateau permeability changes with speed by 2e-17 m² per decade (2.0 standard errors; at v16 no fluid "
        "force fixes it: the force is at or below the elastic law, or K at the field's 1e-09 m² limit or beyond). "
    )


def test_plateaus_at_one_speed_give_no_slope():
    # Real PAAm G: the two curves beside the reference were replicates at 15 µm/s, and the summary read "the plateau
    # permeability changes with speed by -0.12 m² per decade (1.0 standard errors)".
    one_speed = {
        "v15": {"base_speed": 1.4999999999999999e-05, "mean": 1.0785e-16, "std_error": 1.26e-18},
        "v15b": {"base_speed": 1.5e-05, "mean": 1.0729e-16, "std_error": 1.8e-19},
    }
    assert all(math.isnan(value) for value in _weighted_slope(one_speed))
    two_speeds = {**one_speed, "v5": {"base_speed": 5e-6, "mean": 1.2e-16, "std_error": 1e-18}}
    slope, std = _weighted_slope(two_speeds)
    assert slope < 0 and 0 < std < abs(slope)
