"""train.py's checkpoints (a killed run resumes to the same result) and its sweeps; what its stages find on the
shared clean and viscous runs is read in test_diagnosis.py, beside the diagnosis of the same runs (one run a
worker)."""

import json
import subprocess
import sys

import pytest
import torch

from ptwin.fitting import checkpoint
from tests.conftest import CONFIGS, run, settings_for, simulated_set


def quick(*extra):
    return (
        "diagnosis.terms=[]",
        "optim.hybrid.regularisations=[1.0e-2,1.0]",
        "optim.hybrid.iterations=12",
        "optim.hybrid.checkpoint_every=4",
        *extra,
    )


def test_same_seed_same_result_and_a_killed_run_resumes_to_it(tmp_path, coarse_cache, monkeypatch):
    folder = simulated_set(tmp_path / "set", base_speeds=(0.5e-6, 8e-6, 80e-6), samples=400)
    first = run(folder, coarse_cache, tmp_path / "a", *quick()).results["stages"]["hybrid"]
    again = run(folder, coarse_cache, tmp_path / "b", *quick()).results["stages"]["hybrid"]
    assert first == again  # bit for bit

    saves, original = [], checkpoint.save_checkpoint

    def killed_after_second(*args):
        original(*args)
        saves.append(1)
        if len(saves) == 2:
            raise KeyboardInterrupt  # the process dies right after a checkpoint landed

    monkeypatch.setattr(checkpoint, "save_checkpoint", killed_after_second)
    with pytest.raises(KeyboardInterrupt):
        run(folder, coarse_cache, tmp_path / "c", *quick())
    monkeypatch.setattr(checkpoint, "save_checkpoint", original)
    ckpt = tmp_path / "c" / "checkpoint.pt"
    resumed = run(folder, coarse_cache, tmp_path / "d", *quick(f"ckpt_path={ckpt}")).results["stages"]["hybrid"]
    assert resumed == first
    finished = tmp_path / "a" / "checkpoint.pt"  # a finished run: the twin is restored, not trained again
    assert (
        run(folder, coarse_cache, tmp_path / "f", *quick(f"ckpt_path={finished}")).results["stages"]["hybrid"] == first
    )

    with pytest.raises(checkpoint.CheckpointError, match="model.hidden: checkpoint 6, now 4"):
        run(folder, coarse_cache, tmp_path / "e", *quick(f"ckpt_path={ckpt}", "model.hidden=4"))


def test_the_twin_trained_aside_is_the_twin_trained_here_bit_for_bit(tmp_path, coarse_cache):
    # Within one thread, as a run is, the twin trains in a forked child and comes back as its parameters, rebuilt
    # from the same start (``TwinAside``).
    from ptwin.aside import can_fork
    from ptwin.pipeline.identify import identify
    from ptwin.pipeline.prepare import prepare
    from ptwin.pipeline.twin import TwinAside, train_twin
    from ptwin.threads import one_thread

    folder = simulated_set(tmp_path / "set", base_speeds=(0.5e-6, 8e-6, 80e-6), samples=400)
    settings = settings_for(f"data.path={folder}", "pgd=coarse", f"cache_dir={coarse_cache}", *quick()[1:])
    with one_thread():
        p = prepare(settings, progress=lambda line: None)
        permeability = identify(p, settings.optim, progress=lambda line: None, chain=False).base.permeability
        here = train_twin(p, permeability, p.noise_floor, settings, tmp_path / "here")
        lines = []
        forked = can_fork()
        with TwinAside(p, permeability, p.noise_floor, settings, tmp_path / "aside", lines.append) as aside:
            assert aside._aside.forked == forked
            outcome = aside.outcome()
    assert ("(aside," in lines[0]) == forked
    assert (outcome.val_rmse, outcome.iterations, outcome.regularisation) == (
        here.val_rmse,
        here.iterations,
        here.regularisation,
    )
    with torch.no_grad():
        assert torch.equal(outcome.twin.predict(p.samples), here.twin.predict(p.samples))
    assert (tmp_path / "aside" / "checkpoint.pt").is_file()
    assert list((tmp_path / "aside" / "tensorboard").glob("events.out.tfevents.*"))


def test_a_multirun_sweep_leaves_one_run_per_value(tmp_path, coarse_cache):
    folder = simulated_set(tmp_path / "set", base_speeds=(0.5e-6, 80e-6), samples=300)
    sweep = tmp_path / "sweep"
    result = subprocess.run(
        [
            sys.executable,
            "train.py",
            "-m",
            "model.hidden=2,3",
            f"data.path={folder}",
            "pgd=coarse",
            f"cache_dir={coarse_cache}",
            f"hydra.sweep.dir={sweep}",
            *quick("optim.hybrid.iterations=3"),
        ],
        cwd=CONFIGS.parent,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    counts = [
        json.loads((sweep / str(i) / "results.json").read_text())["stages"]["hybrid"]["network_parameters"]
        for i in range(2)
    ]
    assert counts == [2 * 2 + 2 + 2 + 1, 3 * 2 + 3 + 3 + 1]


def test_checkpoint_from_another_basis_is_refused(tmp_path):
    path = tmp_path / "checkpoint.pt"
    checkpoint.save_checkpoint(path, {"step": torch.tensor(1)}, {"seed": 0}, "a" * 64)
    with pytest.raises(checkpoint.CheckpointError, match="PGD basis aaaaaaaaaaaaaaaa"):
        checkpoint.load_checkpoint(path, {"seed": 0}, "b" * 64)
    assert checkpoint.load_checkpoint(path, {"seed": 0, "ckpt_path": "x"}, "a" * 64)["step"] == 1
