"""Close the loop: confounded candidates → the proposed experiment → recorded from the same truth → named."""

import json
from dataclasses import replace

import pytest

from ptwin.data.recordings import write_recordings
from ptwin.synth.cli import main as synth
from ptwin.synth.presets import SOFT_CANTILEVER
from ptwin.synth.simulator import Experiment, Hold, simulate
from tests.conftest import run

pytestmark = pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
QUICK = (
    "optim.hybrid.regularisations=[1.0e-2]",
    "optim.hybrid.iterations=10",
    "diagnosis.terms=[solid_relaxation,pore_pressure_relaxation]",
)


def test_relaxation_confounded_with_pore_pressure_is_named_after_the_proposed_hold(tmp_path, coarse_cache):
    truth = Experiment(**SOFT_CANTILEVER, effects={"solid_relaxation": {"g": 0.1, "tau": 0.1}})
    write_recordings(tmp_path / "before", *simulate(truth))
    before = run(tmp_path / "before", coarse_cache, tmp_path / "run_before", *QUICK)
    groups = before.diagnosis["confounded"]
    assert any({"solid_relaxation", "pore_pressure_relaxation"} <= set(g["terms"]) for g in groups)
    proposal = next(g["next_experiment"] for g in groups if "solid_relaxation" in g["terms"])
    assert proposal["separation"] >= 10 and proposal["duration"] > 0
    assert proposal["protocol"][0]["segment"] == "approach"
    assert (tmp_path / "run_before" / "next_experiment_1.png").is_file()

    augmented = replace(truth, holds=Hold.proposed(proposal))
    write_recordings(tmp_path / "after", *simulate(augmented))
    after = run(tmp_path / "after", coarse_cache, tmp_path / "run_after", *QUICK).diagnosis
    assert [(e["term"], e["confidence"]) for e in after["left_out"]] == [("solid_relaxation", "strong")]
    assert after["permeability"]["corrected"] == pytest.approx(truth.permeability, rel=0.05)


def test_the_synth_command_records_what_a_diagnosis_proposes(tmp_path):
    proposal = {
        "protocol": [
            {"segment": "approach", "base_speed": 15e-6, "to_depth": 0.6e-6},
            {"segment": "hold", "duration": 0.2},
        ],
        "repeats": 2,
    }
    diagnosis = tmp_path / "diagnosis.json"
    diagnosis.write_text(json.dumps({"confounded": [{"terms": ["a", "b"], "next_experiment": proposal}]}))
    common = ["--truth", str(tmp_path / "truth.yaml"), "--speeds", "5e-6", "15e-6", "--samples", "200"]
    synth(["--out", str(tmp_path / "set"), *common, "--next-experiment", str(diagnosis)])
    from ptwin.data.recordings import load_recordings

    recordings = load_recordings(tmp_path / "set")
    assert recordings.curve_ids == ["v5", "v15", "v15h", "v15h2"]
    held = recordings.curve("v15h")
    assert set(held["segment"]) == {"approach", "hold"}
    assert (held[held["segment"] == "hold"]["base_speed"] == 0).all()
    duration = held["time"].iloc[-1] - held[held["segment"] == "hold"]["time"].iloc[0]
    assert duration == pytest.approx(0.2, abs=0.01)
