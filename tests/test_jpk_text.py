"""JPK text exports (``force-save-*.txt``) into recording sets: a simulated export of known values, and where
``PTWIN_JPK_TEXT`` names the ``inst`` folder of the public afmToolkit repository (github.com/rbensua/afmToolkit,
read in place), real ones."""

import os
from pathlib import Path

import numpy as np
import pytest

from ptwin.data.import_afm import main
from ptwin.data.recordings import load_recordings
from tests.conftest import run

COMMON = ["--probe-radius", "5.0e-6", "--viscosity", "1.0e-3", "--thickness", "1.0e-4"]
SPRING_CONSTANT, SENSITIVITY = 0.1, 5.0e-8  # [N/m], [m/V] in the simulated export's header
TRAVEL, DURATION = 1.0e-6, 0.5  # [m], [s] of its extend: 2 µm/s
REAL = Path(os.environ.get("PTWIN_JPK_TEXT", "-"))
real = pytest.mark.skipif(
    not (REAL / "force-save-JPK-3h.txt").is_file(),
    reason="set PTWIN_JPK_TEXT to the inst folder of rbensua/afmToolkit (public JPK text exports)",
)


def write_export(path: Path, segments: list[tuple[str, str, np.ndarray, np.ndarray, np.ndarray]], unit="V") -> None:
    """A JPK text export of ``segments`` (kind, what a pause held, time [s], measured height [m], vertical
    deflection [``unit``]), a block per segment headed as JPK's segmented force settings head theirs; the piezo's
    height reads 90% of the measured one, as a closed-loop scanner's may."""
    settings = [f"# force-settings.segments.size: {len(segments)}"]
    for index, (kind, held, *_) in enumerate(segments):
        settings += [f"# force-settings.segment.{index}.style: {kind}"]
        if kind == "extend":
            settings += [
                f"# force-settings.segment.{index}.duration: {DURATION}",
                f"# force-settings.segment.{index}.z-start: {TRAVEL}",
                f"# force-settings.segment.{index}.z-end: 0.0",
            ]
        if held:
            settings += [f"# force-settings.segment.{index}.pause-option.type: {held}"]
    lines = []
    for index, (kind, _, time, height, deflection) in enumerate(segments):
        lines += ["# TEXT EXPORT" if index == 0 else "#", "# force-settings.type: segmented-force-settings"]
        lines += [*settings, "#", f"# segmentIndex: {index}", f"# segment: {kind}"]
        lines += [
            "# columns: height vDeflection smoothedCapacitiveSensorHeight seriesTime time",
            f"# units: m {unit} m s s",
        ]
        lines += [f"# sensitivity: {SENSITIVITY}", f"# springConstant: {SPRING_CONSTANT}", "#"]
        rows = zip(time, height, deflection)
        lines += [f"{0.9 * h:.9e} {v:.9e} {h:.9e} {t:.9e} {t - time[0]:.9e}" for t, h, v in rows]
    path.write_text("\n".join(lines) + "\n")


def relaxation_export(path: Path, unit: str = "V") -> np.ndarray:
    """A stress relaxation (extend, pause at constant height, retract) written as a text export, its deflection in
    ``unit`` (V or N); returns its force [N] over the extend and the pause. Contact at a third of the travel, a
    Hertz-like rise, a relaxing hold."""
    extend_time = np.linspace(0.0, DURATION, 200)
    height = TRAVEL * (1 - extend_time / DURATION)  # the sensor reads the base's height above its lowest
    depth = np.clip(TRAVEL / 3 - height, 0.0, None)
    extend = 2e-8 + 4e-5 * depth**1.5 / TRAVEL**0.5  # [N]: an offset, then the rise
    pause_time = DURATION + np.linspace(0.002, 1.0, 300)
    pause = extend[-1] * (0.7 + 0.3 * np.exp(-(pause_time - DURATION) / 0.2))
    retract_time = pause_time[-1] + np.linspace(0.002, DURATION, 100)
    volts = 1 / (SPRING_CONSTANT * SENSITIVITY) if unit == "V" else 1.0
    write_export(
        path,
        [
            ("extend", "", extend_time, height, extend * volts),
            ("pause", "constant-height", pause_time, np.zeros_like(pause_time), pause * volts),
            ("retract", "", retract_time, TRAVEL * (retract_time - retract_time[0]) / DURATION, np.zeros(100)),
        ],
        unit,
    )
    return np.concatenate([extend, pause])


def test_a_text_export_of_a_stress_relaxation_becomes_its_approach_and_hold_in_newtons(tmp_path, capsys):
    force = relaxation_export(tmp_path / "force-save-1.txt")
    main([str(tmp_path / "force-save-1.txt"), "--out", str(tmp_path / "set"), *COMMON])
    assert "force-save-1.txt as v2h (the retract (100 samples) not written)" in capsys.readouterr().out
    recordings = load_recordings(tmp_path / "set")
    curve = recordings.curve("v2h")
    assert recordings.meta.spring_constant == SPRING_CONSTANT
    assert list(dict.fromkeys(curve["segment"])) == ["approach", "hold"]
    assert (curve["segment"] == "approach").sum() == 200 and (curve["segment"] == "hold").sum() == 300
    np.testing.assert_allclose(curve["force"], force, rtol=1e-8)  # volts × sensitivity × spring constant
    approach = curve[curve["segment"] == "approach"]
    assert approach["base_speed"].iloc[0] == pytest.approx(TRAVEL / DURATION)
    assert np.ptp(approach["z"]) == pytest.approx(TRAVEL)  # the sensor's travel, not the piezo's 90%
    assert (curve.loc[curve["segment"] == "hold", "base_speed"] == 0).all()


@pytest.mark.parametrize("unit", ["V", "N"])
def test_a_calibration_given_scales_the_force_the_export_calibrated(tmp_path, unit):
    force = relaxation_export(tmp_path / "force-save-1.txt", unit)
    for given, factor in (
        (["--spring-constant", "0.2"], 2.0),
        (["--spring-constant", "0.2", "--sensitivity", "1e-7"], 4.0),
    ):
        main([str(tmp_path / "force-save-1.txt"), "--out", str(tmp_path / f"set{factor}"), *COMMON, *given])
        recordings = load_recordings(tmp_path / f"set{factor}")
        assert recordings.meta.spring_constant == 0.2
        np.testing.assert_allclose(recordings.curves["force"], factor * force, rtol=1e-8)


def test_a_multi_step_export_is_read_for_its_first_ramp_and_hold_saying_what_is_left_out(tmp_path, capsys):
    time = np.linspace(0.0, DURATION, 50)
    noise = np.random.default_rng(0).normal(0.0, 1e-12, 50)  # [N]
    ramp = ("extend", "", time, TRAVEL * (1 - time / DURATION), 1e-8 * np.clip(2 * time / DURATION - 1, 0, 1) + noise)
    hold = ("pause", "constant-height", time + DURATION + 0.01, np.zeros(50), 1e-8 + noise)
    step = ("extend", "", time + 2 * DURATION, -0.1 * TRAVEL * time / DURATION, 2e-8 + noise)
    write_export(tmp_path / "steps.txt", [ramp, hold, step, hold, step], unit="N")
    main([str(tmp_path / "steps.txt"), "--out", str(tmp_path / "set"), *COMMON])
    assert "as v2h (the 2 later steps and what follows (150 samples) not written)" in capsys.readouterr().out
    curve = load_recordings(tmp_path / "set").curve("v2h")
    assert curve["segment"].tolist() == ["approach"] * 50 + ["hold"] * 50


def test_a_pause_of_unknown_hold_and_a_broken_row_are_refused_in_one_line(tmp_path, capsys):
    time = np.linspace(0.0, DURATION, 50)
    ramp = ("extend", "", time, TRAVEL * (1 - time / DURATION), np.zeros(50))
    unknown = [ramp, ("pause", "", time + 1, np.zeros(50), np.zeros(50))]
    for name, segments, words in (
        ("unknown.txt", unknown, "unknown.txt: pause segment 1 held what the export does not say"),
        ("broken.txt", [ramp], "broken.txt: line 20 is not 5 numbers (the columns of segment extend)"),
    ):
        write_export(tmp_path / name, segments)
        if name == "broken.txt":
            lines = (tmp_path / name).read_text().splitlines()
            lines[19] = lines[19].replace("e", "x", 1)
            (tmp_path / name).write_text("\n".join(lines))
        with pytest.raises(SystemExit) as stop:
            main([str(tmp_path / name), "--out", str(tmp_path / "set"), *COMMON])
        error = capsys.readouterr().err.strip()
        assert stop.value.code == 2 and error.count("\n") == 0 and words in error
    assert not (tmp_path / "set").exists()


@real
def test_real_jpk_text_exports_become_a_stress_relaxation_and_an_approach(tmp_path, capsys):
    # afmToolkit's 3h file: extend 1.5 µm in 0.5 s, 10 s at constant height, retract; its 2h file an approach
    # whose relative settings give 120 nm in 0.3 s.
    main([str(REAL / "force-save-JPK-3h.txt"), "--out", str(tmp_path / "relaxation"), *COMMON])
    main([str(REAL / "force-save-JPK-2h.txt"), "--out", str(tmp_path / "approach"), *COMMON])
    out = capsys.readouterr().out
    assert "as v3h (the retract (1024 samples) not written)" in out and "as v0.4 (the retract" in out
    relaxation = load_recordings(tmp_path / "relaxation")
    curve = relaxation.curve("v3h")
    assert (curve["segment"] == "approach").sum() == 1025 and (curve["segment"] == "hold").sum() == 20480
    hold = curve[curve["segment"] == "hold"]
    assert hold["time"].iloc[-1] - hold["time"].iloc[0] == pytest.approx(10.0, abs=0.01)
    assert hold["force"].iloc[-500:].mean() < hold["force"].iloc[:50].mean()  # the force relaxes at constant height
    assert relaxation.meta.spring_constant == pytest.approx(52.91, rel=1e-3)
    approach = load_recordings(tmp_path / "approach").curves
    assert set(approach["segment"]) == {"approach"} and approach["z"].iloc[0] < 0 < approach["z"].iloc[-1]


@real
@pytest.mark.slow  # ~1 min: 21,500 samples of a real stress relaxation through the whole chain
def test_one_real_ramp_and_hold_from_a_text_export_is_diagnosed_in_its_hold(tmp_path, coarse_cache):
    # One curve, one speed: what ptwin can tell, it tells from the hold. The force relaxes at constant height,
    # which the base model (elastic + Darcy at this curve's K) misses; a hereditary term of the vocabulary
    # takes it (power_law_rheology, moderate, with the default basis).
    main([str(REAL / "force-save-JPK-3h.txt"), "--out", str(tmp_path / "set"), *COMMON])
    d = run(tmp_path / "set", coarse_cache, tmp_path / "run", "diagnosis.design=false").diagnosis
    hereditary = {"solid_relaxation", "power_law_rheology", "pore_pressure_relaxation"}
    assert d["mismatch"]["detected"]
    assert {entry["term"] for entry in d["left_out"]} & hereditary
