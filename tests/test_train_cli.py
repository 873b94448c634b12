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


def test_top_level_keys_are_typed_too(tmp_path):
    result = run_train(tmp_path, "seed=abc")
    assert result.returncode != 0
    assert "seed" in result.stderr and "abc" in result.stderr


def test_a_setting_that_composes_but_cannot_run_ends_with_one_line(tmp_path):
    result = run_train(tmp_path, "diagnosis.terms=[solid_viscosity,viscosity]")
    assert result.returncode == 2
    assert (
        result.stderr.strip().splitlines()[-1].startswith("diagnosis.terms: unknown ['viscosity']; the vocabulary is")
    )
    assert "Traceback" not in result.stderr


def test_the_basis_command_builds_where_train_py_looks(tmp_path):
    from ptwin.pgd.cache import cache_path, cached_basis
    from tests.conftest import settings_for

    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "ptwin.basis",
            "pgd=coarse",
            f"cache_dir={tmp_path}",
            f"hydra.run.dir={tmp_path / 'run'}",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    config = settings_for("pgd=coarse", "data.path=-", "cache_dir=-").pgd
    assert cache_path(config, tmp_path).is_file()
    lines = []
    cached_basis(config, tmp_path, progress=lines.append)
    assert lines == [f"reusing PGD basis {cache_path(config, tmp_path)}"]
