import os
from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir

from ptwin.app import register, typed
from ptwin.aside import can_fork
from ptwin.data.recordings import write_recordings
from ptwin.pgd.build import build_basis
from ptwin.pgd.cache import cached_basis
from ptwin.pgd.config import EnrichmentSettings, Grid, PGDConfig, PlaneMesh, ThicknessMesh
from ptwin.pipeline.run import RunResult
from ptwin.pipeline.run import run as run_pipeline
from ptwin.pipeline.settings import Settings
from ptwin.synth.simulator import Experiment, simulate
from ptwin.threads import one_thread

if os.environ.get("PYTEST_XDIST_WORKER"):
    # Workers share the machine's cores: one thread each, or two workers oversubscribe two cores.
    torch.set_num_threads(1)


# The files that run whole diagnoses, heaviest first (seconds of a worker's time, make test at 69217f9: 96, 41, 39,
# 38, 34, 23, 21, 19, 18; the other 31 files 0.1–15 s, 160 s together). make test hands files to its two workers in
# collection order (--no-loadscope-reorder): with these first, the last file a worker takes is a light one. xdist's
# own order, most tests first, handed out five of them last (one_curve, power_law_diagnosis, realism, train_cli and
# training have 3–5 tests each).
HEAVIEST_FIRST = (
    "test_map.py",
    "test_one_curve.py",
    "test_diagnosis.py",
    "test_power_law_diagnosis.py",
    "test_inject.py",
    "test_train_cli.py",
    "test_realism.py",
    "test_holds.py",
    "test_training.py",
)


def pytest_collection_modifyitems(items):
    """The heaviest files first (``HEAVIEST_FIRST``), each file's tests in their own order."""
    rank = {name: i for i, name in enumerate(HEAVIEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


DEMO = Path(__file__).resolve().parents[1] / "data" / "demo"  # the bundled demo set
OPEN_DATA = Path(os.environ.get("PTWIN_OPEN_DATA", "-"))  # open_data/ of github.com/Jhko725/NeuralConstitutiveEq.jl


def needs_open_data(material: str):
    """Skip, saying why, where the public JPK curves of ``material`` (a folder of open_data/) are absent."""
    return pytest.mark.skipif(
        not (OPEN_DATA / material).is_dir(),
        reason="set PTWIN_OPEN_DATA to the open_data folder of Jhko725/NeuralConstitutiveEq.jl (public JPK curves)",
    )


def small_config(**overrides) -> PGDConfig:
    """A coarse basis (seconds to build) with the structure of the real presets."""
    values = dict(
        plane=PlaneMesh(rings=6, edge_grading=2.0),
        thickness=ThicknessMesh(nodes=120, finest=1.0e-7),
        velocity=Grid(1.0e-8, 5.0e-4, 21),
        permeability=Grid(1.0e-19, 1.0e-13, 21),
        contact_radius=Grid(1.0e-7, 5.0e-5, 21),
        aspect_ratio=Grid(0.1, 1.0e5, 121),
        enrichment=EnrichmentSettings(max_modes=80, amplitude_tol=1e-5, output_tol=1e-7),
    )
    values.update(overrides)
    return PGDConfig(**values)


@pytest.fixture(scope="session")
def small_basis():
    return build_basis(small_config(), progress=lambda line: None)


@pytest.fixture(scope="session")
def basis_file(small_basis, tmp_path_factory):
    path = tmp_path_factory.mktemp("basis") / "small.pt"
    small_basis.save(path)
    return path


CONFIGS = Path(__file__).resolve().parents[1] / "configs"


def compose_train(*overrides):
    """The train.py config as Hydra composes it, with ``overrides``."""
    register()
    with initialize_config_dir(config_dir=str(CONFIGS), version_base="1.3"):
        return compose(config_name="train", overrides=list(overrides))


def settings_for(*overrides) -> Settings:
    """The typed settings train.py would run with ``overrides``."""
    return typed(compose_train(*overrides))


@pytest.fixture(scope="session")
def coarse_cache(tmp_path_factory):
    """A cache directory holding the ``coarse`` preset's basis (built once per session)."""
    folder = tmp_path_factory.mktemp("cache")
    cached_basis(settings_for("pgd=coarse", "data.path=-", "cache_dir=-").pgd, folder, progress=lambda _: None)
    return folder


def simulated_set(folder: Path, **experiment) -> Path:
    """A small synthetic recording set (4 speeds × 600 samples) in ``folder``."""
    values = dict(base_speeds=(0.5e-6, 4e-6, 20e-6, 80e-6), samples=600)
    values.update(experiment)
    write_recordings(folder, *simulate(Experiment(**values)))
    return folder


def run(folder, cache, output, *overrides, figures: bool = False, progress=lambda line: None) -> RunResult:
    """The pipeline as train.py runs it, on the coarse basis; ``figures``: drawn, for the tests that read them
    (the rest leave out 1.5–2.5 s of drawing a run); ``progress`` sees its lines."""
    settings = settings_for(
        f"data.path={folder}", "pgd=coarse", f"cache_dir={cache}", f"figures={str(figures).lower()}", *overrides
    )
    return run_pipeline(settings, output, progress=progress)


NO_FORK = "no fork here (not Linux, one core, or an accelerator in the machine): the work aside runs in the caller"


@pytest.fixture
def forking():
    """Within one thread, where ``ptwin.aside`` forks (skipped where it may not)."""
    with one_thread():
        if not can_fork():
            pytest.skip(NO_FORK)
        yield


@pytest.fixture
def two_threads():
    """torch on two threads within the test, the count before given back after."""
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="session")
def default_set(tmp_path_factory) -> Path:
    """``simulated_set`` as it comes (nothing concealed), simulated once a worker (2 s): its readers read it and
    write elsewhere."""
    return simulated_set(tmp_path_factory.mktemp("default"))


@pytest.fixture(scope="session")
def clean_run(default_set, tmp_path_factory, coarse_cache):
    output = tmp_path_factory.mktemp("clean_run")
    return run(default_set, coarse_cache, output, figures=True), output


@pytest.fixture(scope="session")
def viscous_run(tmp_path_factory, coarse_cache):
    folder = simulated_set(tmp_path_factory.mktemp("viscous"), effects={"solid_viscosity": {"gamma": 5.0}})
    # its tests read what is named and fitted, not the experiment proposed (seconds of simulation and refits), and
    # the viscosity's strength fitted alone, profiled as python -m ptwin.inject asks
    output = tmp_path_factory.mktemp("viscous_run")
    return run(folder, coarse_cache, output, "diagnosis.design=false", "diagnosis.profiled=[solid_viscosity]")


@pytest.fixture(scope="session")
def demo_run(tmp_path_factory, coarse_cache):
    return run(DEMO, coarse_cache, tmp_path_factory.mktemp("demo_run"), figures=True)
