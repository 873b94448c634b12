"""train.py as users run it: bad recordings end the run with one line, exit code 2."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).parent.parent


def run_train(tmp_path, *overrides):
    return subprocess.run(
        [sys.executable, "train.py", f"hydra.run.dir={tmp_path / 'run'}", *overrides],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_bad_recording_set_ends_with_one_located_line(tmp_path):
    folder = tmp_path / "bad"
    folder.mkdir()
    (folder / "meta.yaml").write_text(
        "probe_radius: 12\nspring_constant: 2.88\nsample_thickness: 6.0e-3\n"
        "fluid_viscosity: 1.0e-3\nreference_curve: v1\n"
    )
    (folder / "curves.csv").write_text("curve,base_speed,time,z,force\n")
    result = run_train(tmp_path, f"data.path={folder}")
    assert result.returncode == 2
    last = (result.stdout + result.stderr).strip().splitlines()[-1]
    assert last == f"{folder / 'meta.yaml'}: probe_radius 12 m is not SI (micrometres?); write e.g. 12.0e-6"
    assert "Traceback" not in result.stderr


def test_a_typo_in_a_config_key_fails_at_the_command_line(tmp_path):
    result = run_train(tmp_path, "pgd.plane.ringz=3")
    assert result.returncode != 0
    assert "ringz" in result.stderr
