"""train.py as users run it: bad recordings end the run with one line, exit code 2."""

import os
import subprocess
import sys
from pathlib import Path

import hydra
import pandas as pd
import pytest
from hydra.errors import ConfigCompositionException

from ptwin.app import SettingsError, register, run_face
from ptwin.pipeline.prepare import UnsupportedSet, prepare
from tests.conftest import settings_for, simulated_set

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


def test_a_reference_curve_that_barely_indents_is_refused_in_one_line(tmp_path):
    # Its approach in contact is the elastic law: with no sample there, building the law raised IndexError (exit 3)
    folder = simulated_set(tmp_path / "set", z_start=-1.0e-6)
    curves = pd.read_csv(folder / "curves.csv")
    reference = curves["curve"] == "v0.5"
    pressed = reference & (curves["z"] >= 0)
    kept = ~pressed | (pressed.cumsum() <= 19)  # 19 of the reference's samples past contact, its depth > 0 at most
    curves[kept].to_csv(folder / "curves.csv", index=False)
    with pytest.raises(UnsupportedSet) as refused:
        prepare(settings_for(f"data.path={folder}", "cache_dir=-"), progress=lambda _: None)
    line = str(refused.value)
    assert line.startswith(f"{folder / 'curves.csv'}: curve 'v0.5', the reference curve, has ")
    assert "approach samples in contact (20 at least)" in line and "\n" not in line


def test_a_run_whose_output_is_closed_says_so_in_one_line(tmp_path, coarse_cache):
    # ``python train.py | head``: the reader gone, the next progress line raises; no "unexpected ..., report it"
    process = subprocess.Popen(
        [sys.executable, "train.py", f"hydra.run.dir={tmp_path / 'run'}", "pgd=coarse", f"cache_dir={coarse_cache}"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    process.stdout.close()
    stderr = process.communicate(timeout=120)[1]
    assert process.returncode == 2
    assert stderr.strip().splitlines() == [
        "ptwin: the run's output was closed before it ended (piped into a command that stopped reading, such as "
        "head), so the run stopped there; pipe it through `tee FILE` to read it whole"
    ]
    assert not (tmp_path / "run" / "error.log").exists()


def test_a_face_whose_reader_left_after_its_last_line_still_ends_cleanly():
    # exit_now flushes what is still buffered; with the reader gone that raised, a traceback after a finished run
    code = "import sys; from ptwin.app import exit_now; sys.stdout.write('results in …'); exit_now()"
    environment = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # the line stays buffered
    process = subprocess.Popen(
        [sys.executable, "-c", code], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=environment
    )
    process.stdout.close()  # before the child, still importing, writes a byte
    stderr = process.communicate(timeout=60)[1]
    assert (process.returncode, stderr) == (0, b"")


def test_a_broken_pipe_elsewhere_is_reported_as_unexpected(tmp_path, monkeypatch):
    from ptwin.app import one_line_errors

    with (tmp_path / "out.txt").open("w") as stdout:  # an output that is read: the pipe that broke is another's
        monkeypatch.setattr(sys, "stdout", stdout)
        with pytest.raises(SystemExit) as ended, one_line_errors(tmp_path):
            raise BrokenPipeError("a worker's socket")
    assert ended.value.code == 3
    assert "BrokenPipeError: a worker's socket" in (tmp_path / "error.log").read_text()


def test_a_typo_in_a_config_key_fails_at_the_command_line_in_one_line(tmp_path):
    result = run_train(tmp_path, "pgd.plane.ringz=3")
    assert result.returncode == 2
    assert result.stderr.splitlines() == [
        "Could not override 'pgd.plane.ringz': Key 'ringz' not in 'PlaneMesh'; "
        "`python train.py --cfg job` prints every setting with its value"
    ]


def test_top_level_keys_are_typed_too(tmp_path):
    result = run_train(tmp_path, "seed=abc")
    assert result.returncode == 2
    assert result.stderr.splitlines() == [
        "Error merging override seed=abc: Value 'abc' of type 'str' could not be converted to Integer; "
        "`python train.py --cfg job` prints every setting with its value"
    ]


@pytest.mark.parametrize("added", ["+foo=1", "+optim.hybrid.lambdas=[1]", "+data.paht=x"])
def test_a_key_added_that_no_setting_reads_is_refused_in_one_line(added):
    # Hydra's +KEY=… adds a key to a typed config and the dataclass leaves it out: the run went on without it
    key = added[1:].partition("=")[0]
    with pytest.raises(SettingsError) as refused:
        settings_for(added, "data.path=-", "cache_dir=-")
    assert str(refused.value).startswith(f"{key}: no such setting, so nothing would read it (added by +{key}=…); ")
    assert "\n" not in str(refused.value)


@pytest.mark.parametrize(
    ("arguments", "line"),
    [
        (["seed=["], "seed=[: no viable alternative at input '['; write it as Hydra's override grammar says"),
        (["pgd=fine"], "In 'train': Could not find 'pgd/fine'; pgd is one of coarse, default, paper, precise"),
        (["hydra.run.dir=/proc/run"], "/proc/run: No such file or directory; give hydra.run.dir a folder that can"),
        (["-m", "hydra.sweep.dir=/proc/runs"], "/proc/runs: No such file or directory; give hydra.sweep.dir a folder"),
    ],
)
def test_a_command_line_hydra_cannot_compose_or_place_ends_with_one_line(arguments, line, monkeypatch, capsys):
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    monkeypatch.setattr(sys, "argv", ["train.py", *arguments])
    with pytest.raises(SystemExit) as ended:
        run_face(_train_face())
    assert ended.value.code == 2
    said = capsys.readouterr().err.splitlines()
    assert len(said) == 1 and said[0].startswith(line)
    assert "HYDRA_FULL_ERROR" not in os.environ


def test_a_user_who_asked_hydra_for_full_errors_gets_them(monkeypatch):
    monkeypatch.setenv("HYDRA_FULL_ERROR", "1")
    monkeypatch.setattr(sys, "argv", ["train.py", "seed=abc"])
    with pytest.raises(ConfigCompositionException):
        run_face(_train_face())


def _train_face():
    """train.py's face, composing its config and running nothing."""
    register()

    @hydra.main(version_base="1.3", config_path=str(ROOT / "configs"), config_name="train")
    def main(cfg) -> None:
        pytest.fail(f"composed {cfg}")

    return main


def test_a_setting_that_composes_but_cannot_run_ends_with_one_line(tmp_path):
    result = run_train(tmp_path, "diagnosis.terms=[solid_viscosity,viscosity]")
    assert result.returncode == 2
    assert (
        result.stderr.strip().splitlines()[-1].startswith("diagnosis.terms: unknown ['viscosity']; the vocabulary is")
    )
    assert "Traceback" not in result.stderr


# A value out of its setting's range, and the start of the one line that refuses it. Each was run by train.py
# before it was checked: a ZeroDivisionError, a broadcast error or an untyped ValueError ended in "unexpected …
# please report it" (exit 3), and a negative damping, learning rate or tolerance, a plateau beyond the curve's
# depth or a fit of no steps ran to a verdict on nonsense (a base model 113× the noise, no plateau K). The pgd
# ones ended python -m ptwin.basis in Hydra's traceback (exit 1).
OUT_OF_RANGE = [
    ("optim.hybrid.regularisations=[]", "optim.hybrid.regularisations must be one λ ≥ 0 or more"),
    ("optim.hybrid.regularisations=[-1.0]", "optim.hybrid.regularisations must be one λ ≥ 0 or more"),
    ("optim.hybrid.regularisations=[0.01,inf]", "optim.hybrid.regularisations must be one λ ≥ 0 or more"),
    ("optim.hybrid.iterations=-5", "optim.hybrid.iterations must be 0 or more"),
    ("optim.hybrid.damping=-1", "optim.hybrid.damping must be LM's first damping, positive"),
    ("optim.hybrid.tolerance=-1", "optim.hybrid.tolerance must be a relative fall"),
    ("optim.hybrid.learning_rate.physics=0", "optim.hybrid.learning_rate must be a positive rate"),
    ("optim.hybrid.newton_c1=-1", "optim.hybrid.newton_c1 must be 0 or more"),
    ("optim.hybrid.newton_iterations=-1", "optim.hybrid.newton_iterations must be 0 or more"),
    ("optim.hybrid.checkpoint_every=0", "optim.hybrid.checkpoint_every must be 1 or more"),
    ("optim.physics_fit.iterations=0", "optim.physics_fit.iterations must be 1 or more"),
    ("optim.pointwise.iterations=-1", "optim.pointwise.iterations must be 1 or more"),
    ("optim.pointwise.plateau_from=1.5", "optim.pointwise.plateau_from must be a fraction"),
    ("split.fractions=[0.5,0.5,0.5]", "split.fractions must be three positive numbers summing to 1"),
    ("split.mode=sideways", "split.mode must be 'random' or 'curve'"),
    ("data.smoothing=2", "data.smoothing must be a fraction from 0 to 1"),
    ("model.hidden=0", "model.hidden must be 1 or more neurons"),
    ("model.elastic_nodes=1", "model.elastic_nodes must be 2 or more"),
    ("model.elastic_smoothing=-0.1", "model.elastic_smoothing must be a fraction"),
    ("diagnosis.block=0", "diagnosis.block must be 1 or more samples"),
    ("diagnosis.bic_margin=-1", "diagnosis.bic_margin must be 0 or more"),
    ("diagnosis.heldout_margin=1", "diagnosis.heldout_margin must be a fraction"),
    ("permeability=-1", "permeability must be a positive starting K"),
    ("pgd.plane.rings=0", "pgd.plane.rings must be 1 or more"),
    ("pgd.thickness.finest=1", "pgd.thickness.finest must be the top element's thickness, between 0 and 1"),
    ("pgd.enrichment.max_modes=0", "pgd.enrichment.max_modes must be 1 or more"),
    ("pgd.richardson_order=0", "pgd.richardson_order must be positive"),
]


@pytest.mark.parametrize(("override", "line"), OUT_OF_RANGE, ids=[o for o, _ in OUT_OF_RANGE])
def test_a_value_out_of_its_range_is_one_line_naming_the_setting(override, line):
    with pytest.raises(SettingsError) as refused:
        settings_for(override, "data.path=-", "cache_dir=-")
    message = str(refused.value)
    assert message.startswith(line) and "\n" not in message


def test_the_map_and_inject_faces_refuse_out_of_range_in_the_same_words():
    from ptwin.pipeline.settings import InjectSettings, MapSettings

    with pytest.raises(ValueError, match=r"^map.workers must be 0 or more \(0: one per core\), e.g. 2; got -1$"):
        MapSettings(workers=-1)
    with pytest.raises(
        ValueError, match=r"^inject.sizes must be positive multiples of the term's strength.*; got \[\]$"
    ):
        InjectSettings(sizes=[])


@pytest.mark.parametrize(
    "override",
    [
        "optim.hybrid.iterations=0",
        "optim.hybrid.regularisations=[0.0]",
        "optim.hybrid.newton_iterations=0",
        "model.elastic_smoothing=0",
        "data.smoothing=0",
        "diagnosis.block=1",
        "optim.pointwise.plateau_from=0",
        "model.elastic_nodes=2",
    ],
)
def test_the_ends_of_each_range_are_settings_that_run(override):
    settings_for(override, "data.path=-", "cache_dir=-")


def test_out_of_range_at_the_command_line_is_exit_2_and_one_line(tmp_path):
    result = run_train(tmp_path, "optim.hybrid.checkpoint_every=0")
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        "optim.hybrid.checkpoint_every must be 1 or more LM steps, e.g. 10; got 0"
    ]


def test_a_held_out_curve_the_set_lacks_is_one_line_naming_the_set(tmp_path, coarse_cache):
    result = run_train(
        tmp_path,
        "pgd=coarse",
        f"cache_dir={coarse_cache}",
        "split.mode=curve",
        "split.held_out_curve=v3",
        "figures=false",
    )
    assert result.returncode == 2
    last = result.stderr.strip().splitlines()[-1]
    assert last.endswith(
        "data/demo: split.held_out_curve 'v3' is not a fitted curve; pick one of ('v2', 'v8', 'v40', 'v80')"
    )
    assert "Traceback" not in result.stderr


def test_the_basis_command_builds_where_train_py_looks(tmp_path):
    from ptwin.pgd.cache import cache_path, cached_basis

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


def test_train_py_trains_the_twin_aside_and_finds_what_one_process_finds_bit_for_bit(
    tmp_path, coarse_cache, monkeypatch, forking
):
    # train.py trains its twin in a forked child while the diagnosis fits the base model and each term, draws the
    # figures of stages 1–3 in another while the diagnosis goes on, and the corrected model's in a third while it
    # finds their intervals (``ptwin.aside``); here, with forks refused, all of it is done in this process. The
    # short baselines of the simulated set make the diagnosis read the noise off the twin's residual.
    import json

    import ptwin.aside
    import ptwin.pipeline.twin
    from ptwin.data.noise import RESIDUAL
    from tests.conftest import run, simulated_set

    folder = simulated_set(tmp_path / "set", base_speeds=(0.5e-6, 8e-6, 80e-6), samples=400)
    overrides = ("optim.hybrid.regularisations=[1.0e-2,1.0]", "optim.hybrid.iterations=12", "diagnosis.design=false")
    result = run_train(tmp_path, f"data.path={folder}", "pgd=coarse", f"cache_dir={coarse_cache}", *overrides)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "LM over the λ grid (aside, while the diagnosis fits what does not need it)" in result.stdout
    monkeypatch.setattr(ptwin.pipeline.twin, "can_fork", lambda: False)
    monkeypatch.setattr(ptwin.aside, "can_fork", lambda: False)
    lines = []
    here = run(folder, coarse_cache, tmp_path / "here", *overrides, figures=True, progress=lines.append)
    assert not any("(aside," in line for line in lines)
    assert here.diagnosis["noise"]["source"].startswith(RESIDUAL)
    aside = tmp_path / "run"
    assert json.loads((aside / "diagnosis.json").read_text()) == here.diagnosis
    assert json.loads((aside / "results.json").read_text())["stages"]["hybrid"] == here.results["stages"]["hybrid"]
    report = (tmp_path / "here" / "report.md").read_text().replace(str(tmp_path / "here"), str(aside))
    assert (aside / "report.md").read_text() == report
    for name in here.figures:
        assert (aside / f"{name}.png").read_bytes() == (tmp_path / "here" / f"{name}.png").read_bytes(), name
    # train.py ends its process at once (``ptwin.app.exit_now``): what it said and wrote is all there
    assert result.stdout.rstrip().splitlines()[-1].startswith(f"results in {aside} (")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    ran, made_here = (EventAccumulator(str(o / "tensorboard")).Reload().Tags() for o in (aside, tmp_path / "here"))
    assert ran["scalars"] and sorted(ran["scalars"]) == sorted(made_here["scalars"])
    assert ran["images"] and sorted(ran["images"]) == sorted(made_here["images"])
