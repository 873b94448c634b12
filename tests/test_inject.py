"""What a set could have shown: a known term added to recordings through the cantilever balance,
found with its size; and on data ptwin did not write (a shared development set with real PAAm noise)."""

import json
import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir

from ptwin.app import register, typed
from ptwin.data.recordings import load_recordings
from ptwin.fitting.physics_fit import fit_with_starts
from ptwin.physics.samples import Samples
from ptwin.pipeline.inject import (
    BASE_PERMEABILITY,
    LADDER,
    Own,
    Trial,
    added_force,
    detection,
    detection_limits,
    detection_section,
    judged_peak,
    native_strength,
)
from ptwin.pipeline.prepare import prepare
from tests.conftest import CONFIGS, OPEN_DATA, needs_open_data, simulated_set

QUICK = ("optim.hybrid.regularisations=[1.0e-2]", "optim.hybrid.iterations=10")
SHARED_NULL = Path(__file__).resolve().parents[2] / "shared" / "bench-sets" / "p03_null_real_paam_noise" / "data"


def inject_settings(folder, cache, *overrides):
    register()
    with initialize_config_dir(config_dir=str(CONFIGS), version_base="1.3"):
        cfg = compose("inject", [f"data.path={folder}", "pgd=coarse", f"cache_dir={cache}", *QUICK, *overrides])
    return typed(cfg)


@pytest.mark.parametrize(("term", "params"), [("solid_viscosity", {"gamma": 5.0}), ("cantilever_drag", {"b": 5e-4})])
def test_a_term_added_is_the_force_the_cantilever_balance_gives_with_it(
    tmp_path, coarse_cache, monkeypatch, term, params
):
    # The simulator solves the balance k_c(z − w) = F(w, …) + ΔF at each z: the same set simulated with the term and
    # without it (the same noise) differ by the force a recording shows of it, less than ΔF where the sample takes a
    # share (a soft cantilever here, k_c 0.3 N/m against up to 0.23 for the sample). At first order (ΔF over the gain
    # 1 + s/k_c at the recorded depth) the viscosity was 0.41 of the noise std off in rms, the drag 2.9 (one linear
    # step with the depth's rate, 0.37 and 3.4); Newton on the depth alone 0.049 and 0.38; on the depth and its
    # rate, 0.010 and 0.070.
    import ptwin.pipeline.inject as inject

    common = dict(base_speeds=(0.5e-6, 4e-6, 20e-6, 80e-6), samples=600, spring_constant=0.3)
    without = simulated_set(tmp_path / "without", **common)
    exact = load_recordings(simulated_set(tmp_path / "with", **common, effects={term: params})).curves["force"]
    exact = exact.to_numpy() - load_recordings(without).curves["force"].to_numpy()
    prepared = prepare(inject_settings(without, coarse_cache), progress=lambda _: None)
    base = fit_with_starts(prepared.make_model, (), prepared.samples, prepared.split.train)
    ids = prepared.recordings.curves["curve"].unique()

    def error(added):
        return np.sqrt(np.mean((np.concatenate([added[c] for c in ids]) - exact) ** 2)) / prepared.noise.std

    solved = added_force(prepared, term, params, base)
    if term == "solid_viscosity":  # no contact radius, no viscous force, whatever the balance
        samples = Samples.from_curves(prepared.curves)
        free = (samples.depth <= 0).numpy()
        assert np.all(np.concatenate([solved[c] for c in samples.curve_ids])[free] == 0.0)
    monkeypatch.setattr(inject, "BALANCE_STEPS", 0)  # one linear step: the first order, with the depth's rate
    first = added_force(prepared, term, params, base)
    assert error(solved) < 0.05 * error(first)


def test_a_balance_step_the_model_cannot_evaluate_leaves_the_force_added_at_the_step_before(
    default_set, coarse_cache, monkeypatch
):
    # A later step moves the depth (deeper, for a force that lowers it): a model that refuses it there (the fluid
    # layer off its grid) ends the steps, and the force added is the last one evaluated, here the linear step from
    # nothing.
    import ptwin.pipeline.inject as inject

    prepared = prepare(inject_settings(default_set, coarse_cache), progress=lambda _: None)
    base = fit_with_starts(prepared.make_model, (), prepared.samples, prepared.split.train)
    monkeypatch.setattr(inject, "BALANCE_STEPS", 0)
    first = added_force(prepared, "solid_viscosity", {"gamma": 5.0}, base)
    monkeypatch.setattr(inject, "BALANCE_STEPS", 8)
    calls, total = [], inject.total

    def refusing(forces):
        calls.append(1)
        if len(calls) > 3:  # the recorded depth and the linear step's (twice: ∂F/∂ẇ) are evaluated; no later depth
            raise ValueError("off the fluid layer's grid")
        return total(forces)

    monkeypatch.setattr(inject, "total", refusing)
    kept = added_force(prepared, "solid_viscosity", {"gamma": 5.0}, base)
    assert all(np.array_equal(kept[c], first[c]) for c in first) and np.abs(first["v80"]).max() > 0


def test_a_term_added_starts_where_the_elastic_force_does_whatever_the_reference_correction(tmp_path, coarse_cache):
    # The reference's own contact correction is a nuisance only the rate forces see; where the data do not pin it,
    # it wanders within the onset (62 nm before it on bench-set p03). A viscosity added from there would push on
    # samples the recording shows free of the sample.
    from ptwin.fitting.physics_fit import fit_physics

    folder = simulated_set(tmp_path / "set", contact_point="estimate", z_start=-1e-6)
    prepared = prepare(inject_settings(folder, coarse_cache), progress=lambda _: None)
    base = fit_physics(prepared.make_model(), prepared.samples, prepared.split.train)
    with torch.no_grad():
        base.model.contact.reference.fill_(-50e-9)
    added = added_force(prepared, "solid_viscosity", {"gamma": 5.0}, base)
    assert base.model.contact.reference.item() == -50e-9  # the base fit is left as it was
    samples = Samples.from_curves(prepared.curves)
    with torch.no_grad():
        free = (base.model.depth(samples) <= 0).numpy()
    shown = np.concatenate([added[curve] for curve in samples.curve_ids])
    assert free.any() and np.all(shown[free] == 0.0)
    assert np.abs(shown).max() > 0


def test_a_viscosity_added_to_a_set_is_found_with_its_size(default_set, tmp_path, coarse_cache):
    settings = inject_settings(default_set, coarse_cache, "inject.sizes=[1.0]", "diagnosis.design=false")
    trials = detection(settings, tmp_path / "run", progress=lambda _: None)
    as_recorded, added = trials
    assert not as_recorded.confidence  # the clean set names nothing, and says what gamma fitted alone came to
    assert abs(as_recorded.alone) < 1.0 and f"gamma {as_recorded.alone:.3g} fitted alone" in as_recorded.verdict(
        Own("gamma", 0.0)
    )
    assert (
        as_recorded.permeability
        == json.loads((tmp_path / "run" / "as-recorded" / "diagnosis.json").read_text())["permeability"]["base"]
    )
    assert added.confidence and added.found == pytest.approx(5.0, rel=0.4)
    report = (tmp_path / "run" / "as-recorded" / "report.md").read_text()
    assert "## What these recordings could have shown" in report and "The smallest gamma named: 5" in report
    injected = load_recordings(tmp_path / "run" / "size-1" / "recordings")
    assert "ptwin.inject: solid_viscosity (gamma 5) added" in injected.meta.notes


def test_a_verdict_says_which_other_terms_the_diagnosis_named():
    # 5 Pa s added to real agarose came back as pore_pressure_relaxation + solid_relaxation; "not named" alone hid it.
    others = (("pore_pressure_relaxation", "strong"), ("solid_relaxation", "weak"))
    missed = Trial(1.0, 5.0, 36.6, "", None, [None, None], False, True, -5.72, others)
    assert missed.verdict(Own("gamma", 0.0)) == (
        "not named (gamma -5.72 fitted alone, not physical); the diagnosis named pore_pressure_relaxation (strong) + "
        "solid_relaxation (weak)"
    )
    named = Trial(2.0, 10.0, 73.2, "weak", 9.79, [8.61, 11.1], False, True, others=others[1:])
    assert named.verdict(Own("gamma", 0.0)).endswith(
        "9.79 over the recordings' own, 0.979× the size added; beside it solid_relaxation (weak)"
    )
    alone = Trial(2.0, 10.0, 73.2, "weak", 9.79, [8.61, 11.1], False, True)
    assert "beside" not in alone.verdict(Own("gamma", 0.0)) and "the diagnosis named" not in alone.verdict(
        Own("gamma", 0.0)
    )


def test_other_terms_the_recordings_name_as_they_are_are_said_to_be_theirs():
    # A real creep names solid_relaxation + power_law_rheology as recorded and with a viscosity added: the viscosity
    # was not read as them. The names are read off the two diagnoses (``_trial``).
    from ptwin.pipeline.inject import _trial
    from ptwin.pipeline.run import RunResult

    def outcome(*named):
        left_out = [{"term": term, "confidence": "moderate"} for term in named]
        diagnosis = {"left_out": left_out, "unexplained": False, "notes": [], "confounded": []}
        return RunResult({}, diagnosis, {}, {"solid_viscosity": {"gamma": -248.0}}, 2e-16)

    recorded = outcome("solid_relaxation", "power_law_rheology")
    both = _trial(1.0, 4.57, 64.0, recorded, "solid_viscosity", "gamma", recorded)
    assert both.verdict(Own("gamma", 0.0)).endswith(
        "the diagnosis named solid_relaxation (moderate) + power_law_rheology (moderate), as in the recordings as "
        "they are"
    )
    one = _trial(
        1.0, 4.57, 64.0, outcome("pore_pressure_relaxation", "power_law_rheology"), "solid_viscosity", "gamma", recorded
    )
    assert one.verdict(Own("gamma", 0.0)).endswith(
        "+ power_law_rheology (moderate); power_law_rheology as in the recordings as they are"
    )
    assert _trial(0.0, None, 0.0, recorded, "solid_viscosity", "gamma").recorded == ()


def test_a_strength_fitted_alone_is_said_as_the_data_fix_it():
    # Bench-set p03 (real PAAm noise) with a solid relaxation of 32× the noise added (g 0.164): "not named (g 4.46
    # fitted alone)", the value a flat profile left the fit at. Profiled (``Diagnosis.alone``), it is said as a bound.
    flat = Trial(32.0, 0.164, 32.0, "", None, [None, None], False, True, 4.46, alone_interval=[None, None])
    own = Own("g", 0.0806)
    assert flat.verdict(own) == "not named (g fitted alone: not fixed by these data)"
    closed = replace(flat, alone=0.55, alone_interval=[0.292, 1.86])
    assert closed.verdict(own) == "not named (g fitted alone: 0.55 (95%: 0.292 to 1.86))"
    above = replace(flat, alone_interval=[0.3, None])
    assert above.verdict(own) == "not named (g fitted alone: > 0.3 (95%; the data set no upper limit))"
    structured = replace(flat, alone_interval=None, alone_misses_data=True, unexplained=True)
    assert structured.verdict(own).startswith("unexplained (g fitted alone: 4.46 (from a model that misses the data")
    assert (
        replace(flat, alone_interval=None).verdict(own) == "not named (g 4.46 fitted alone, not physical)"
    )  # not profiled


def test_the_recordings_own_strength_a_size_is_read_over_is_said_as_the_data_fix_it():
    # Bench-set p04 with a solid relaxation added: "named (weak), g 0.0586 (95%: 0.0517 to 0.0666)" beside "a size
    # found is read over g 0.0651, the recordings' own", a bare value whatever the data made of it.
    named = Trial(64.0, 0.0643, 64.0, "weak", 0.0586, [0.0517, 0.0666], False, True)
    closed = Own("g", 0.0651, 0.0, [0.051, 0.079])
    assert closed.words() == "a size found is read over the recordings' own g 0.0651 (95%: 0.051 to 0.079)"
    assert named.verdict(closed).endswith("fit g 0.0651 (95%: 0.051 to 0.079): the size found is not read over it")
    assert Own("g", 4.46, 0.0, [None, None]).words().endswith("own g 4.46, not fixed by these data")
    below = Own("g", 0.0651, 0.0, [None, 0.3]).fitted()
    assert below == "g 0.0651, though the data say only g < 0.3 (95%; the data set no lower limit)"
    structured = Own("g", 0.0651, 0.0, [None, None], misses_data=True).fitted()
    assert structured.startswith("g 0.0651 (from a model that misses the data")
    assert Own("g", 0.0651).fitted() == "g 0.0651"  # not profiled


def test_the_recordings_own_strength_is_the_one_their_diagnosis_fitted_and_profiled():
    # A real PAAm place said "gamma fitted alone: 0.246 (95%: 0 to 0.85)" and "read over the recordings' own gamma
    # 0.246 (95%: 0 to 1.11)" in one line: the own was fitted again, under the noise model before the diagnosis's
    # cap. Nothing is fitted where the diagnosis fitted the term (no recordings are given here to fit).
    recorded = Trial(0.0, None, 0.0, "", None, [None, None], False, True, 0.246, alone_interval=[0.0, 0.85])
    own = native_strength(None, "solid_viscosity", 60, None, recorded)
    assert own.fitted() == "gamma 0.246 (95%: 0 to 0.85)"
    structured = native_strength(None, "solid_viscosity", 60, None, replace(recorded, alone_misses_data=True))
    assert structured.fitted().startswith("gamma 0.246 (from a model that misses the data")
    not_physical = native_strength(
        None, "solid_viscosity", 60, None, replace(recorded, alone=-2.37, alone_interval=None)
    )
    assert not_physical.value is None and not_physical.words().endswith("own fit of gamma failed or is not physical")


def test_an_own_strength_fitted_where_the_term_does_nothing_is_read_over_not_read_whole():
    # A real PAAm place at two speeds fitted "alpha fitted alone: 0 (95%: 0 to 0.0109)" as recorded, physical: an
    # own compared with the strength that removes the term by value had been said to have failed or not to be
    # physical, and a size found "over the recordings' own" where it had been read whole.
    at_zero = Own("alpha", 0.0, 0.0, [0.0, 0.0109])
    assert at_zero.words() == "a size found is read over the recordings' own alpha 0 (95%: 0 to 0.0109)"
    named = Trial(1.0, 0.0319, 31.7, "weak", 0.0296, [0.02, 0.04], False, True)
    assert named.verdict(at_zero).endswith("; 0.0296 over the recordings' own, 0.928× the size added")
    assert named.verdict(Own("alpha", None)).endswith("; read whole, 0.928× the size added")
    assert Own("alpha", None).beyond(0.0296) == 0.0296 and Own("M", None, math.inf).beyond(1.0e4) == 1.0e4


def test_a_term_read_as_another_it_cannot_be_told_from_says_so():
    # Real-noise PAAm null (bench-set p03) with g 0.33 of solid_relaxation added: the diagnosis named
    # strain_dependent_permeability (weak) and listed the two as confounded; the verdict read as a wrong answer.
    named = (("strain_dependent_permeability", "weak"),)
    rival = ("strain_dependent_permeability",)
    missed = Trial(64.0, 0.328, 64.0, "", None, [None, None], False, True, 1.86, named, confounded=rival)
    assert missed.verdict(Own("g", 0.0)) == (
        "not named (g 1.86 fitted alone, not physical); the diagnosis named strain_dependent_permeability (weak) in "
        "its place: these recordings cannot tell the two apart"
    )
    both = (("pore_pressure_relaxation", "strong"), *named)
    partly = Trial(64.0, 0.328, 64.0, "", None, [None, None], False, True, 1.86, both, confounded=rival)
    assert partly.verdict(Own("g", 0.0)).endswith(
        "the diagnosis named pore_pressure_relaxation (strong) + strain_dependent_permeability (weak); "
        "strain_dependent_permeability (weak) in its place: these recordings cannot tell the two apart"
    )
    # Real PAAm (`PAA_speed {5,10,15}_4nN`) with 5 Pa·s added: the rival was named as recorded too, so it was not read
    # in the term's place; it read "…(weak), as in the recordings as they are in its place: …".
    before = replace(missed, recorded=rival)
    assert before.verdict(Own("g", 0.0)).endswith(
        "the diagnosis named strain_dependent_permeability (weak), as in the recordings as they are; "
        "strain_dependent_permeability (weak) explains the data as well as the term added: "
        "these recordings cannot tell the two apart"
    )


def test_a_size_found_of_a_term_that_vanishes_as_its_strength_grows_adds_in_its_reciprocal():
    # Bench-set p01 with a pore relaxation added (M 1.07e4 Pa): found 1.03e4 over the recordings' own 2.05e6, read
    # as "-2.04e+06 over the recordings' own". Its force is ∝ 1/M: the added 1/M is the difference of the two.
    own = Own("M", 2.05e6, math.inf)
    named = Trial(1.0, 1.07e4, 64.7, "weak", 1.03e4, [9.75e3, 1.09e4], False, True)
    # the size found beside the size added in 1/M too: 1/1.04e4 over 1/1.07e4
    beyond = 1 / (1 / 1.03e4 - 1 / 2.05e6)
    assert named.verdict(own).endswith(
        f"; {beyond:.3g} over the recordings' own, {1.07e4 / beyond:.3g}× the size added"
    )
    assert own.beyond(3e6) is None and Own("M", None, math.inf).beyond(1e4) == pytest.approx(1e4)
    weaker = Trial(1.0, 1.07e4, 64.7, "weak", 3e6, [2e6, 4e6], False, True)
    assert weaker.verdict(own).endswith(
        "; the recordings as they are fit M 2.05e+06: the size found is not read over it"
    )
    # Bench-set p04 with g 0.064 of solid_relaxation added: found 0.058 (tau 0.11 s), read as "-1.76 over the
    # recordings' own", the g 1.8 they fit as they are at tau 542 s: another shape of the term.
    relaxation = Trial(64.0, 0.0643, 64.0, "weak", 0.0582, [0.0513, 0.0662], False, True)
    assert relaxation.verdict(Own("g", 1.82)).endswith("fit g 1.82: the size found is not read over it")
    # Real PAAm C as recorded, its viscosity fitted at −2.05 Pa·s: "read over gamma none, the recordings' own".
    assert (
        Own("gamma", None).words()
        == "a size found is read whole: the recordings' own fit of gamma failed or is not physical"
    )
    assert Own("M", None, math.inf).words().endswith("the recordings' own fit of M failed or is not physical")
    assert Own("M", 2.05e6, math.inf).words() == "a size found is read over the recordings' own M 2.05e+06"


def test_a_term_not_named_comes_with_the_base_model_permeability():
    # Real agarose B with 5 Pa s added: the base model's K fell from the limit of no fluid force to 1.17e-15 m²,
    # its fluid force carrying the viscosity; the verdict said only "unexplained (gamma 2.51 fitted alone)".
    as_recorded = Trial(0.0, None, 0.0, "", None, [None, None], True, True, -2.48, permeability=1.58e-9)
    added = Trial(1.0, 5.0, 35.2, "", None, [None, None], True, True, 2.51, permeability=1.17e-15)
    assert as_recorded.verdict(Own("gamma", 0.0)) == (
        "unexplained (gamma -2.48 fitted alone, not physical; the base model's K at the field's 1e-09 m² limit or "
        "beyond: no fluid force)"
    )
    assert added.verdict(Own("gamma", 0.0)) == (
        "unexplained (gamma 2.51 fitted alone, not physical; the base model's K 1.17e-15 m²)"
    )
    nothing_fitted = Trial(1.0, 5.0, 35.2, "", None, [None, None], False, False, permeability=2e-15)
    assert nothing_fitted.verdict(Own("gamma", 0.0)) == (
        "not named (no candidate in these recordings; the base model's K 2e-15 m²)"
    )


def test_a_size_named_beside_unexplained_structure_is_given_without_an_interval():
    # Real agarose A with 5 Pa s added: the viscosity named beside structure no term explains. "gamma not fixed by
    # these data" hid the size it took; the words say where the missing interval comes from instead.
    named = Trial(1.0, 5.0, 42.8, "weak", 6.15, [None, None], True, True)
    assert named.verdict(Own("gamma", 0.615)) == (
        "named (weak), gamma 6.15 (from a model that misses the data: no interval holds); 5.54 over the recordings' "
        "own, 1.11× the size added"
    )
    # Real agarose B with g 0.546 of solid_relaxation added: named beside such structure at g 1.41e+03, which the
    # verdict read as "1.41e+03 over the recordings' own" and the ladder as found; the size added says otherwise.
    relaxation = Trial(64.0, 0.546, 64.0, "weak", 1410.0, [None, None], True, True)
    assert relaxation.verdict(Own("g", 0.0)).endswith("1.41e+03 over the recordings' own, 2.58e+03× the size added")


def test_the_section_says_which_rule_left_an_added_term_unnamed():
    # Real PAAm with 5 Pa s added: the held-out test pruned it; the user reads that, not a bare "not named".
    pruned = "solid_viscosity pruned: on the validation samples solid_viscosity takes 8 units of χ² off the residual"
    trials = [
        Trial(0.0, None, 0.0, "", None, [None, None], False, True, 1.6, why=("solid_viscosity: as recorded",)),
        Trial(1.0, 5.0, 26.0, "", None, [None, None], False, True, 7.03, why=(pruned,)),
        Trial(2.0, 10.0, 52.0, "moderate", 11.2, [9.8, 12.5], False, True),
    ]
    section = detection_section("solid_viscosity", trials, Own("gamma", 0.0), ["solid_viscosity"])
    assert f"- gamma 5 added: {pruned}" in section and section[2].endswith(BASE_PERMEABILITY)
    assert not any("as recorded" in line and line.startswith("- ") for line in section)  # the sizes added only
    assert sum(line.startswith("- ") for line in section) == 1  # none for the size named


@pytest.mark.slow
@pytest.mark.skipif(not SHARED_NULL.is_dir(), reason="the shared development sets (../shared/bench-sets) are absent")
def test_a_viscosity_added_to_real_noise_is_named(tmp_path, coarse_cache):
    settings = inject_settings(SHARED_NULL, coarse_cache, "inject.sizes=[2.0]")
    trials = detection(settings, tmp_path / "run", progress=lambda _: None)
    assert trials[-1].confidence  # 63× the noise at its peak


def viscosity_added_to_real_curves(tmp_path: Path, material: str, files: list[str], size: float = 1.0) -> tuple:
    """(as recorded, ``size`` × 5 Pa·s added) ``Trial``s of the real curves ``files`` ('speed 5/<name>.tab', under
    open_data/``material``), imported as one recording set, with the default basis and the whole chain (its runs
    under ``tmp_path``/run)."""
    from ptwin.data.import_afm import main as import_afm

    recordings = tmp_path / "recordings"
    import_afm(
        [*(str(OPEN_DATA / material / name) for name in files), "--out", str(recordings), "--probe-radius", "5e-6"]
        + ["--viscosity", "1e-3", "--thickness", "8e-5"]
    )
    register()
    with initialize_config_dir(config_dir=str(CONFIGS), version_base="1.3"):
        overrides = [f"data.path={recordings}", f"cache_dir={tmp_path / 'cache'}", f"inject.sizes=[{size}]"]
        cfg = compose("inject", overrides)
    return detection(typed(cfg), tmp_path / "run", progress=lambda _: None)


@pytest.mark.slow
@needs_open_data("PAAM hydrogel")
def test_a_viscosity_added_to_a_real_paam_spot_is_named_with_its_size(tmp_path):
    # Real recordings that ptwin did not write (Abuhattum et al. 2022, PAAm): one spot at 5 and 15 µm/s, 5 Pa·s
    # added through the cantilever balance, everything else real. Named with its size over the
    # recordings' own (6.26 over 0.005, moderate, since the balance is solved; 6.10 over 0.001, weak beside
    # unexplained structure, at first order), with the default basis and the whole chain.
    files = ["speed 5/PAA_speed 5_4nN_3.tab", "speed 15/PAA_speed 15_4nN.tab"]
    as_recorded, added = viscosity_added_to_real_curves(tmp_path, "PAAM hydrogel", files)
    assert not as_recorded.confidence
    own = max(as_recorded.alone, 0.0)  # what γ fitted alone gives the recordings as they are
    assert added.confidence and added.found - own == pytest.approx(5.0, rel=0.4)


@pytest.mark.slow
@needs_open_data("Agarose")
def test_a_viscosity_added_to_real_agarose_curves_of_three_places_is_fitted_with_its_size_but_not_named(tmp_path):
    # Real agarose (Abuhattum et al. 2022), five curves at 5, 10 and 15 µm/s at one position of three map sessions
    # (import_afm says so: three places). With 5 Pa·s added the viscosity fitted alone finds its size (4.38 over the
    # recordings' own 0.61; 4.76 with the force added at first order), and it is not named. Until stop 105 the
    # recordings as they are left structure no term explains (the places differ), and the term that took part of
    # it fell to the held-out tests: on curves left out it predicted 1.16× worse. Since stop 106 the places' baseline
    # slopes (at 5 µm/s −1.32e-5 and −0.47e-5 N/m, standard errors near 4e-7) read as a drift the noise model lacks
    # (χ² 61 on 3 degrees of freedom, ``noise.drift``), which the tests then simulate: a set of several places (the
    # import warns that a recording set is one spot) reads its places' tilts as noise, and the misfit between the
    # places as within it. Nothing is named either way, and the viscosity is listed beside the base model.
    files = [
        "speed 5/Agarose_speed 5_2nN.tab",
        "speed 5/Agarose_speed 5_2nN_1.tab",
        "speed 10/Agarose_speed 10_2nN.tab",
    ]
    files += ["speed 15/Agarose_speed 15_2nN.tab", "speed 15/Agarose_speed 15_2nN-1.tab"]
    as_recorded, added = viscosity_added_to_real_curves(tmp_path, "Agarose", files)
    drift = json.loads((tmp_path / "run" / "as-recorded" / "diagnosis.json").read_text())["noise"]["drift"]
    assert drift["dof"] == 3 and drift["share"] > 0
    assert not as_recorded.confidence and not added.confidence
    own = max(as_recorded.alone, 0.0)
    assert added.alone - own == pytest.approx(5.0, rel=0.4)
    assert any("solid_viscosity lowers the BIC" in why and "listed beside the base model" in why for why in added.why)


# One position of one agarose map session (Abuhattum et al. 2022) at 5, 10 and 15 µm/s.
AGAROSE_PLACE = ["speed 5/Agarose_speed 5_2nN_3.tab", "speed 10/Agarose_speed 10_2nN-1.tab"]
AGAROSE_PLACE += ["speed 15/Agarose_speed 15_2nN-3.tab"]


@pytest.mark.slow
@needs_open_data("Agarose")
def test_a_viscosity_added_to_one_real_agarose_place_is_named_with_its_size_and_predicts_the_test_samples(tmp_path):
    # Real agarose (Abuhattum et al. 2022): the curves at 5, 10 and 15 µm/s of one position of one map session,
    # 10 Pa·s added (65× the noise at its peak). As recorded nothing is named (γ fitted alone −4.1, not physical);
    # with the viscosity added it is named with its size (9.53; 9.6 at first order) and the corrected model predicts
    # the test samples better than the base model (1.48e-11 against 2.27e-11 N): what issue 26 asks of a few Pa·s,
    # here of 10, on a place nothing was tuned on. With 5 Pa·s the base model's fluid force, K from 6.7e-11 to
    # 7.0e-16 m², carries it, predicting the test samples to the noise (1.51e-11 N, the noise std 1.59e-11): the
    # data cannot name a term there.
    as_recorded, added = viscosity_added_to_real_curves(tmp_path, "Agarose", AGAROSE_PLACE, size=2.0)
    assert not as_recorded.confidence
    assert added.confidence and added.found - max(as_recorded.alone, 0.0) == pytest.approx(10.0, rel=0.4)
    fit = json.loads((tmp_path / "run" / "size-2" / "run" / "diagnosis.json").read_text())["fit"]
    assert fit["corrected"]["test_rmse"] < fit["base"]["test_rmse"]


@pytest.mark.slow
@needs_open_data("Agarose")
def test_a_strength_the_base_model_s_k_carries_is_given_an_interval_not_a_point_on_real_agarose(tmp_path):
    # The place above, its curves at 5 and 15 µm/s (another at 15 µm/s), with 5 Pa·s added: the base model's fluid
    # force carries it (K 1.2e-10 → 5.0e-15 m²), and gamma fitted alone sits near 0, its curvature barely fixing it
    # (so did the three curves above, until the velocity's window grew from the contact: gamma alone 2.7 there now).
    # Its profile's first step went 1.96 Wald std out and the refits warm from there never came back, so every
    # point read as closing the side: "gamma fitted alone: 6.23e-10 (95%: 0 to 6.23e-10)", a bound the data never
    # set. From the fit's own values too, the upper side closes where the data put it (5.1 Pa·s, by hand, at 4.9
    # added on the three curves).
    place = [AGAROSE_PLACE[0], "speed 15/Agarose_speed 15_2nN-2.tab"]
    _, added = viscosity_added_to_real_curves(tmp_path, "Agarose", place, size=1.0)
    _, high = added.alone_interval
    assert added.alone < 1.0 and (high is None or high > 1.0)


def test_values_that_do_not_match_the_terms_parameters_are_refused_in_one_line():
    from ptwin.pipeline.settings import InjectSettings

    assert InjectSettings("solid_relaxation", [0.2, 0.1]).scaled(2.0) == {"g": 0.4, "tau": 0.1}
    with pytest.raises(ValueError, match=r"inject.values of solid_relaxation are its parameters in the order"):
        InjectSettings("solid_relaxation", [5.0])
    with pytest.raises(ValueError, match=r"inject.term contact_offset cannot be added: a contact offset moves where"):
        InjectSettings("contact_offset", [1e-7])


@pytest.mark.parametrize(
    ("term", "values", "sizes", "said"),
    [
        ("solid_viscosity", [-1.0], [1.0], r"gamma -1 is no physical solid_viscosity \(gamma < 0\)"),
        ("power_law_rheology", [0.3], [1.0, 2.0], r"alpha 0.6 \(inject.sizes 2\) is no physical .* \(alpha ≥ 0.5\)"),
        ("pore_pressure_relaxation", [0.0], [1.0], r"M 0 is no physical pore_pressure_relaxation \(M ≤ 0\)"),
        ("solid_relaxation", [0.2, -0.1], [1.0], r"tau -0.1 is no physical solid_relaxation \(tau ≤ 0\)"),
        ("solid_viscosity", [math.inf], [1.0], r"gamma inf is no physical solid_viscosity \(gamma is not finite\)"),
    ],
)
def test_values_no_material_has_are_refused_in_one_line(term, values, sizes, said):
    # A viscosity of -1 Pa·s was added to real PAAm and diagnosed ("unexplained"), as if a user could have asked it.
    from ptwin.pipeline.settings import InjectSettings

    with pytest.raises(ValueError, match=rf"^inject.values: {said}; give values in its physical range") as refused:
        InjectSettings(term, values, sizes)
    assert "\n" not in str(refused.value)
    InjectSettings(term, [abs(v) if math.isfinite(v) and v else 0.1 for v in values], [1.0])  # inside it: taken


def test_each_terms_sizes_are_read_off_its_added_force_weak_to_strong(default_set, coarse_cache):
    # The ladder's sizes reach the peaks asked for (bracketed on a grid of the added force, then bisected), the pore
    # term's by a smaller M (its strength grows as M falls).
    from ptwin.fitting.physics_fit import fit_physics
    from ptwin.pipeline.inject import LADDER, _ladder

    settings = inject_settings(default_set, coarse_cache)
    prepared = prepare(settings, progress=lambda _: None)
    base = fit_physics(prepared.make_model(), prepared.samples, prepared.split.train)
    for term in ("solid_viscosity", "pore_pressure_relaxation"):
        ladder = _ladder(prepared, term, base)
        strength = next(iter(ladder[0][1]))
        values = [params[strength] for _, params in ladder]
        for peak, params in ladder:
            assert judged_peak(prepared, added_force(prepared, term, params, base)) == pytest.approx(peak, rel=0.02)
        assert values == sorted(values, reverse=term == "pore_pressure_relaxation")
        assert [p for p, _ in ladder] == list(LADDER[: len(ladder)])


def test_a_ladder_size_is_found_where_its_peak_grows_steeply_or_starts_from_nothing():
    # Interpolated once (log-log), a strain-dependent permeability on real agarose peaked at 5.6× the noise for 8.
    from ptwin.pipeline.inject import PEAK_TOLERANCE, _crossing

    steep = _crossing(math.exp, 8.0, 1.0, math.e, 10.0, math.exp(10.0))
    assert math.exp(steep) == pytest.approx(8.0, rel=PEAK_TOLERANCE)

    def from_nothing(strength):
        return max(strength - 1.0, 0.0)

    assert from_nothing(_crossing(from_nothing, 4.0, 1.0, 0.0, 10.0, 9.0)) == pytest.approx(4.0, rel=PEAK_TOLERANCE)


def test_the_peak_of_a_term_added_is_read_on_the_samples_the_diagnosis_judges(tmp_path, coarse_cache):
    # On one ramp-and-hold curve the approach is the elastic law, no data: a viscosity's force, largest where the
    # approach ends (1.06 nN) and gone within a few samples of the hold (0.79 nN at its first), counts on the hold.
    from ptwin.data.recordings import write_recordings
    from ptwin.fitting.physics_fit import fit_physics
    from ptwin.synth.simulator import Experiment, Hold, simulate

    experiment = Experiment(base_speeds=(), holds=(Hold(3e-6, 2.0, 10e-6),), z_start=-3e-6, sample_rate=2000.0)
    write_recordings(tmp_path / "set", *simulate(experiment))
    prepared = prepare(inject_settings(tmp_path / "set", coarse_cache), progress=lambda _: None)
    base = fit_physics(prepared.make_model(), prepared.samples, prepared.split.train)
    added = added_force(prepared, "solid_viscosity", {"gamma": 5.0}, base)
    (hold,) = prepared.fitted
    in_hold, everywhere = (np.abs(added[hold.curve][mask]).max() for mask in (hold.in_contact, slice(None)))
    assert judged_peak(prepared, added) == pytest.approx(in_hold / prepared.noise.std)
    assert in_hold < everywhere


def test_a_term_the_recordings_name_already_is_not_added_up_the_ladder(tmp_path, coarse_cache):
    # Every size of it would be named: the ladder would read the recordings, not the size (a real creep named its
    # solid relaxation at 8× the noise for a fifteenth of the g it holds). The report gives what they hold.
    folder = simulated_set(tmp_path / "set", effects={"solid_viscosity": {"gamma": 5.0}})
    settings = inject_settings(folder, coarse_cache, "inject.term=all", "diagnosis.terms=[solid_viscosity]")
    lines = []
    assert detection_limits(settings, tmp_path / "run", progress=lines.append) == {"solid_viscosity": []}
    assert re.fullmatch(
        r"  \[1/1\] solid_viscosity: named in the recordings as they are \(\w+\), gamma .*; not added", lines[1]
    )
    report = (tmp_path / "run" / "as-recorded" / "report.md").read_text()
    # what they hold, as the data fix it
    held = re.search(
        r"`solid_viscosity` \| named in the recordings as they are \(gamma ([0-9.]+) \(95%: ([0-9.]+) to ([0-9.]+)\)\)"
        ": not added",
        report,
    )
    assert float(held.group(1)) == pytest.approx(5.0, rel=0.05)
    assert float(held.group(2)) < 5.0 < float(held.group(3))


@pytest.mark.parametrize("reached", [0, 1])
def test_a_term_whose_sizes_never_reach_the_ladder_says_so_as_it_goes(tmp_path, coarse_cache, monkeypatch, reached):
    # Real agarose (three speeds at one place): a pore relaxation peaks below 8× the noise at every M tried. The
    # report's table said so, but the progress went from [2/5] to [4/5] without a word for it. On real PAAm it
    # reached 16× (M 226 Pa, not named) and stopped there, the progress silent on why no larger size came.
    from types import SimpleNamespace

    import ptwin.pipeline.inject as inject

    folder = simulated_set(tmp_path / "set")
    settings = inject_settings(folder, coarse_cache, "inject.term=all", "diagnosis.terms=[solid_viscosity]")
    sizes = [(8.0, {"gamma": 1.0})][:reached]  # the sizes that reach a peak: none, or the first only
    monkeypatch.setattr(inject, "_ladder", lambda *_: sizes)
    missed = SimpleNamespace(confidence=None, peak=8.0, added=1.0, verdict=lambda _: "not named (as if)")
    monkeypatch.setattr(inject, "_added", lambda *_: missed)  # no diagnosis: only the words are tested
    lines = []
    assert detection_limits(settings, tmp_path / "run", progress=lines.append) == {
        "solid_viscosity": [missed] * reached
    }
    peak = LADDER[reached]
    assert lines[-1].startswith(f"  [1/1] solid_viscosity: its peak stays below {peak:g}× the noise for gamma")
    assert lines[-1].endswith(": no larger size tried" if reached else ": not added")


def test_recordings_that_name_as_many_terms_as_are_fitted_together_say_another_needs_more():
    # The public JPK creep names solid_relaxation + power_law_rheology as recorded: with diagnosis.max_terms 2 no term
    # added beside them both can be named, whatever its size; in place of one it can (a brain creep's viscosity).
    from types import SimpleNamespace

    from ptwin.pipeline.inject import _full
    from ptwin.pipeline.run import RunResult

    def named(*terms):
        return RunResult({}, {"left_out": [{"term": term} for term in terms]}, {}, {})

    settings = SimpleNamespace(diagnosis=SimpleNamespace(max_terms=2))
    assert _full(named("solid_relaxation", "power_law_rheology"), settings)[-1] == (
        "The recordings as they are name solid_relaxation + power_law_rheology, diagnosis.max_terms (2) already: a "
        "term added is named beside both only with diagnosis.max_terms=3; within 2, only in place of one of them."
    )
    assert _full(named("solid_relaxation"), settings) == [] and _full(named(), settings) == []


def test_a_term_not_added_because_named_is_told_from_one_whose_sizes_never_reach_the_ladder():
    from ptwin.pipeline.inject import limits_section

    native = {"solid_relaxation": Own("g", 0.148), "cantilever_drag": Own("b", 0.0)}
    rows = limits_section({"solid_relaxation": [], "cantilever_drag": []}, native, {"solid_relaxation"})[-2:]
    assert rows[0] == "| `solid_relaxation` | named in the recordings as they are (g 0.148): not added | – | – | – |"
    assert rows[1].startswith("| `cantilever_drag` | its peak stays below 8× the noise for b 0.001 to 1000 times")


def test_a_term_whose_sizes_stop_short_of_the_ladder_says_where_its_peak_stays():
    # The shared p03 (real PAAm noise): a pore relaxation peaks at 16× the noise at M 89.9 Pa and below 32× at every M
    # tried, so its ladder ends there; the table says why it tried nothing larger.
    from ptwin.pipeline.inject import limits_section

    def missed(m, peak):
        return Trial(1.0, m, peak, "", None, [], False, True, alone=4e4)

    native = {"pore_pressure_relaxation": Own("M", 4e4, absent=math.inf)}
    found = {"pore_pressure_relaxation": [missed(418.0, 8.0), missed(89.9, 16.1)]}
    (row,) = limits_section(found, native, set())[-1:]
    assert row.startswith(
        "| `pore_pressure_relaxation` | not named up to a peak of 16× the noise; its peak stays below 32× the noise "
        "for M 0.001 to 1000 times a typical one (as physical) | – | – | M 89.9 Pa (16×: not named (M 4e+04 fitted "
        "alone, not physical))"
    )


def test_a_dimensionless_size_is_said_without_a_unit_and_a_dimensional_one_with_it():
    # Real agarose (inject.term=all): "| m 13.9 – |" for a strain-dependent K, the dash an axis label's "no unit".
    from ptwin.pipeline.inject import limits_section

    def trial(size, peak, named):
        found = size if named else None
        return Trial(
            1.0, size, peak, "strong" if named else "", found, [0.8 * size, 1.2 * size], False, True, alone=size
        )

    native = {"strain_dependent_permeability": Own("m", 0.0, absent=0.0), "solid_viscosity": Own("gamma", 0.0)}
    found = {
        "strain_dependent_permeability": [trial(9.52, 16.0, False), trial(13.9, 31.6, True)],
        "solid_viscosity": [trial(7.66, 64.0, True)],
    }
    strain, viscosity = limits_section(found, native, set())[-2:]
    assert strain.startswith("| `strain_dependent_permeability` | m 13.9 | 31.6 |") and "| m 9.52 (16×" in strain
    assert viscosity.startswith("| `solid_viscosity` | gamma 7.66 Pa s | 64.0 |")


@pytest.mark.slow
def test_the_detection_limit_of_every_candidate_term_is_in_the_report(default_set, tmp_path, coarse_cache):
    # A contact offset is a candidate at known contacts, but no force added stands for it (``NOT_INJECTED``): added
    # to bench-set p01 its fit found the size, the offset's own check rejected it, and another term was named.
    terms = "diagnosis.terms=[solid_viscosity,contact_offset]"
    settings = inject_settings(default_set, coarse_cache, "inject.term=all", terms)
    lines = []
    found = detection_limits(settings, tmp_path / "run", progress=lines.append)
    trials = found["solid_viscosity"]
    assert trials[-1].confidence and all(not t.confidence for t in trials[:-1])  # up the ladder until named
    assert trials[-1].found == pytest.approx(trials[-1].added, rel=0.4)
    assert found["contact_offset"] == [] and lines[-1].startswith("  [2/2] contact_offset: not added: a contact offset")
    assert len(lines) == 2 + len(trials)  # a line as each size is diagnosed, and one for the term not added
    report = (tmp_path / "run" / "as-recorded" / "report.md").read_text()
    assert "## What these recordings could have shown" in report
    assert f"| `solid_viscosity` | gamma {trials[-1].added:.3g} Pa s |" in report
    assert "| `contact_offset` | not added: a contact offset moves where the recorded force starts" in report


def test_a_drag_free_offsets_remove_is_said_to_be_no_candidate_and_becomes_no_other_term(tmp_path, coarse_cache):
    # Two speeds with estimated contacts: each curve's baseline level is removed, and the drag (b·v, a level per
    # curve) with it; the report must say so, not "not shown up to", and nothing else may be named instead.
    folder = simulated_set(tmp_path / "set", base_speeds=(4e-6, 40e-6), contact_point="estimate", z_start=-1e-6)
    settings = inject_settings(
        folder, coarse_cache, "inject.term=cantilever_drag", "inject.values=[1.0e-4]", "diagnosis.design=false"
    )
    trials = detection(settings, tmp_path / "run", progress=lambda _: None)
    assert trials[-1].peak > 8 and not any(t.confidence or t.candidate for t in trials)
    added = json.loads((tmp_path / "run" / "size-1" / "run" / "diagnosis.json").read_text())
    assert added["left_out"] == [] and not added["unexplained"]
    report = (tmp_path / "run" / "as-recorded" / "report.md").read_text()
    assert "cantilever_drag was no candidate in these recordings (the curves' baseline levels" in report
    # named, never shown: on real PAAm the drag's depth shift left "unexplained" where a strain-dependent K was weak
    assert "drag with it): no size of it can be named in them." in report
