"""One ramp-and-hold curve per spot, the standard poroelastic measurement: its approach is the elastic
law, its hold the data, and a concealed relaxation is named with K within 5% (issue 23)."""

import pytest

from ptwin.data.recordings import write_recordings
from ptwin.synth.simulator import Experiment, Hold, simulate
from tests.conftest import run

pytestmark = pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")


@pytest.mark.parametrize(
    "effects",
    [
        {"solid_relaxation": {"g": 0.2, "tau": 0.5}},
        {"pore_pressure_relaxation": {"M": 3.0e4}},
        {"power_law_rheology": {"alpha": 0.1}},
    ],
    ids=lambda effects: next(iter(effects)),
)
def test_one_ramp_and_hold_names_the_relaxation_and_fixes_k(effects, tmp_path, coarse_cache):
    # 2 kHz: the pore pressure drains in τ_p ≈ 10 ms here, 20 samples (at 1 kHz its 10 samples are too few
    # for the structure test's 50-sample blocks, and nothing is named).
    truth = Experiment(
        base_speeds=(), holds=(Hold(3e-6, 2.0, 10e-6),), z_start=-3e-6, sample_rate=2000.0, effects=effects
    )
    write_recordings(tmp_path / "set", *simulate(truth))
    d = run(tmp_path / "set", coarse_cache, tmp_path / "run", "diagnosis.design=false").diagnosis
    assert [entry["term"] for entry in d["left_out"]] == list(effects)
    assert d["permeability"]["corrected"] == pytest.approx(truth.permeability, rel=0.05)
    assert any("relaxes by" in note for note in d["notes"])
