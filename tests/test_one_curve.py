"""One ramp-and-hold curve per spot, the standard poroelastic measurement: its approach is the elastic
law, its hold the data, and a concealed relaxation is named with K within 5% (issue 23)."""

import pytest
import torch

from ptwin.data.recordings import write_recordings
from ptwin.synth.simulator import Experiment, Hold, simulate
from tests.conftest import run


@pytest.mark.parametrize(
    ("effects", "figures"),
    [
        pytest.param({"solid_relaxation": {"g": 0.2, "tau": 0.5}}, True, id="solid_relaxation-drawn"),
        pytest.param({"pore_pressure_relaxation": {"M": 3.0e4}}, False, id="pore_pressure_relaxation"),
        pytest.param({"power_law_rheology": {"alpha": 0.1}}, False, id="power_law_rheology"),
    ],
)
def test_one_ramp_and_hold_names_the_relaxation_and_fixes_k(effects, figures, tmp_path, coarse_cache):
    # 2 kHz: the pore pressure drains in τ_p ≈ 10 ms here, 20 samples (at 1 kHz its 10 samples are too few
    # for the structure test's 50-sample blocks, and nothing is named).
    truth = Experiment(
        base_speeds=(), holds=(Hold(3e-6, 2.0, 10e-6),), z_start=-3e-6, sample_rate=2000.0, effects=effects
    )
    write_recordings(tmp_path / "set", *simulate(truth))
    d = run(tmp_path / "set", coarse_cache, tmp_path / "run", "diagnosis.design=false", figures=figures).diagnosis
    assert (tmp_path / "run" / "holds_force_time.png").is_file() == figures
    assert ("![holds_force_time](holds_force_time.png)" in (tmp_path / "run" / "report.md").read_text()) == figures
    assert [entry["term"] for entry in d["left_out"]] == list(effects)
    assert d["permeability"]["corrected"] == pytest.approx(truth.permeability, rel=0.05, abs=0)
    assert any("relaxes by" in note for note in d["notes"])


def test_one_ramp_and_hold_with_its_contact_estimated_keeps_the_contact_the_approach_shows(tmp_path, coarse_cache):
    # With one curve the reference's hold is all the data; moving the reference's contact 1.7–2.8 µm into the
    # 3 µm indentation (the rate forces then start late) lowered χ² by more than chance, with a standard error
    # of microns: not a contact its onset (65 nm) allows, so held, and K comes out right.
    from ptwin.fitting.physics_fit import fit_physics

    truth, _, prepared = _prepared_relaxation_hold(
        tmp_path, coarse_cache, z_start=-3e-6, contact_point="estimate", contact_error=1e-7
    )
    model = prepared.make_model(("solid_relaxation",))
    fit = fit_physics(model, prepared.samples, prepared.split.train)
    assert not model.contact.reference.requires_grad and model.contact.reference.item() == 0.0
    assert fit.permeability == pytest.approx(truth.permeability, rel=0.05, abs=0)


def test_noise_measured_on_the_residual_keeps_the_samples_as_fitted(tmp_path, coarse_cache):
    # A baseline too short for the noise's correlation: it is measured on the twin's residual and the samples are
    # rebuilt with it. They must be the fitted ones: of the reference only its hold (its approach is the law), not
    # the curve as recorded (641 approach samples came back in contact when they were rebuilt from it).
    from ptwin.data.noise import RESIDUAL, rests_on_short_records
    from ptwin.pipeline.prepare import fitted_samples
    from ptwin.pipeline.run import _residual_noise

    truth, settings, prepared = _prepared_relaxation_hold(tmp_path, coarse_cache, z_start=-0.02e-6)
    assert rests_on_short_records(prepared.noise)
    twin = prepared.make_model.twin(truth.permeability, 1e-9, prepared.samples, prepared.split.train)
    noise = _residual_noise(prepared, twin.predict, settings.diagnosis.block, 1, RESIDUAL)
    rebuilt, _ = fitted_samples(prepared.fitted, noise, "cpu", prepared.reference, prepared.noise_gain)
    assert rebuilt.noise_inflation != prepared.samples.noise_inflation
    assert torch.equal(rebuilt.in_contact, prepared.samples.in_contact)
    assert torch.equal(rebuilt.pins_contact, prepared.samples.pins_contact)


def _prepared_relaxation_hold(tmp_path, coarse_cache, **experiment):
    """One 3 µm ramp-and-hold (2 s, 2 kHz) concealing a solid relaxation, written and prepared on the coarse
    basis: (the truth, the settings, ``Prepared``)."""
    from ptwin.pipeline.prepare import prepare
    from tests.conftest import settings_for

    truth = Experiment(
        base_speeds=(),
        holds=(Hold(3e-6, 2.0, 10e-6),),
        sample_rate=2000.0,
        effects={"solid_relaxation": {"g": 0.2, "tau": 0.5}},
        **experiment,
    )
    write_recordings(tmp_path / "set", *simulate(truth))
    settings = settings_for(f"data.path={tmp_path / 'set'}", "pgd=coarse", f"cache_dir={coarse_cache}")
    return truth, settings, prepare(settings, progress=lambda line: None)
