"""Close the loop: confounded candidates → the proposed experiment → recorded from the same truth → named."""

import json
from dataclasses import replace

import pytest

from ptwin.data.recordings import write_recordings
from ptwin.synth.cli import main as synth
from ptwin.synth.presets import SOFT_CANTILEVER
from ptwin.synth.simulator import Experiment, Hold, simulate
from tests.conftest import run

QUICK = (
    "optim.hybrid.regularisations=[1.0e-2]",
    "optim.hybrid.iterations=10",
    "diagnosis.terms=[solid_relaxation,pore_pressure_relaxation]",
)


@pytest.mark.slow  # up to three diagnoses of a growing set (~1–3 min); make discover-bench's loop suite runs it too
def test_relaxation_on_a_soft_set_is_named_strong_once_the_proposed_experiments_are_recorded(tmp_path, coarse_cache):
    # Three approach curves: solid relaxation cannot be told from the base model or from pore relaxation.
    # Each round records every experiment proposed to tell solid_relaxation from a rival, from the same
    # truth, and diagnoses again; the loop closes in at most three rounds, and each proposal came true:
    # the rival it was to separate is no longer confounded with solid_relaxation afterwards.
    truth = Experiment(**SOFT_CANTILEVER, effects={"solid_relaxation": {"g": 0.1, "tau": 0.1}})
    recorded: tuple = ()
    for round in range(3):
        folder = tmp_path / f"round{round}"
        write_recordings(folder, *simulate(replace(truth, holds=recorded)))
        d = run(folder, coarse_cache, tmp_path / f"run{round}", *QUICK, figures=True).diagnosis
        if [(e["term"], e["confidence"]) for e in d["left_out"]] == [("solid_relaxation", "strong")]:
            break
        groups = [g for g in d["confounded"] if "solid_relaxation" in g["terms"]]
        assert groups and all(g.get("next_experiment") for g in groups), d["mismatch"]["summary"]
        for group in groups:
            proposal = group["next_experiment"]
            assert proposal["separation"] >= 10 and proposal["duration"] > 0
            assert proposal["protocol"][0]["segment"] == "approach"
        assert (tmp_path / f"run{round}" / "next_experiment_1.png").is_file()
        recorded += tuple(hold for g in groups for hold in Hold.proposed(g["next_experiment"]))
    assert [(e["term"], e["confidence"]) for e in d["left_out"]] == [("solid_relaxation", "strong")]
    assert d["permeability"]["corrected"] == pytest.approx(truth.permeability, rel=0.05, abs=0)


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
