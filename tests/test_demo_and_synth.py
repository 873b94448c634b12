"""The bundled demo and the synth command line."""

import re
from pathlib import Path

import pandas as pd
import pytest
import yaml

from ptwin.data.kinematics import curve_kinematics
from ptwin.data.recordings import load_recordings
from ptwin.synth.cli import main

DEMO = Path(__file__).parent.parent / "data"


def test_demo_loads_and_its_noise_floor_is_the_truth():
    truth = yaml.safe_load((DEMO / "demo.truth.yaml").read_text())
    demo = load_recordings(DEMO / "demo")
    assert demo.curve_ids == ["v0.5", "v2", "v8", "v40", "v80"]
    assert list(truth["effects"]) == ["pore_pressure_relaxation"]
    for curve in curve_kinematics(demo):
        assert curve.noise_floor == pytest.approx(truth["noise_std"], rel=0.1), curve.curve


@pytest.mark.slow
def test_demo_is_what_its_documented_command_writes(tmp_path):
    main(
        [
            "--out",
            str(tmp_path / "demo"),
            "--truth",
            str(tmp_path / "truth.yaml"),
            "--effect",
            "pore_pressure_relaxation:M=3.0e4",
        ]
    )
    pd.testing.assert_frame_equal(load_recordings(tmp_path / "demo").curves, load_recordings(DEMO / "demo").curves)


def test_synth_writes_a_loadable_set_and_its_truth_outside(tmp_path):
    main(
        [
            "--out",
            str(tmp_path / "set"),
            "--truth",
            str(tmp_path / "truth.yaml"),
            "--samples",
            "200",
            "--speeds",
            "1e-6",
            "2e-5",
            "--effect",
            "solid_viscosity:gamma=5.0",
        ]
    )
    assert load_recordings(tmp_path / "set").curve_ids == ["v1", "v20"]
    truth = yaml.safe_load((tmp_path / "truth.yaml").read_text())
    assert truth["effects"] == {"solid_viscosity": {"gamma": 5.0}}


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--effect", "viscosity:gamma=1"], "TERM:PARAM=VALUE"),
        (["--effect", "solid_viscosity:gamma=abc"], "'abc' is not a number"),
        (["--effect", "solid_relaxation:g=0.2"], "missing parameter"),
        # Each below ended in a traceback (IndexError, "scale < 0", "array must not contain infs or NaNs").
        (["--effect", "solid_viscosity:gamma=-3"], r"is not physical \(gamma < 0\)"),
        (["--effect", "pore_pressure_relaxation:M=-3"], r"is not physical \(M must be positive\)"),
        (["--effect", "contact_offset:delta=5e-6"], r"is not physical \(\|delta\| ≥ rho/4"),
        (["--samples", "0"], "--samples must be 20 or more"),
        (["--noise", "-1"], "--noise must be 0 or more"),
        (["--probe-radius", "0"], "--probe-radius must be positive"),
        # the radius first: read against 0 m the offset's range blamed the offset ("|delta| ≥ rho/4 = 0 m")
        (["--probe-radius", "0", "--effect", "contact_offset:delta=1e-8"], "--probe-radius must be positive"),
        (["--speeds", "0", "2e-6"], "--speeds must be positive"),
        (["--seed", "-1"], "--seed must be 0 or more"),
        (["--noise-correlation", "1"], "--noise-correlation must be a lag-1 autocorrelation"),
        (["--replicates", "0"], "--replicates must be 1 or more"),
    ],
)
def test_synth_refuses_bad_effects_and_options_out_of_range_in_one_line(tmp_path, capsys, arguments, message):
    # Exit code 2 and one line on stderr, as every face refuses what a user can fix (the synth exited 1).
    with pytest.raises(SystemExit) as stop:
        main(["--out", str(tmp_path / "set"), "--truth", str(tmp_path / "truth.yaml"), *arguments])
    said = capsys.readouterr().err
    assert stop.value.code == 2 and said.count("\n") == 1 and re.search(message, said)
    assert not (tmp_path / "set").exists()
