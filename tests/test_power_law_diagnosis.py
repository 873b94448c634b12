"""Power-law rheology through the whole diagnosis, fast: named with its exponent where the speeds fix it,
each hereditary term claiming only its own hold, and a K that says when a weak power law leaves it unfixed."""

import pytest

from ptwin.data.recordings import write_recordings
from ptwin.synth.presets import SOFT_CANTILEVER
from ptwin.synth.simulator import Experiment, Hold, simulate
from tests.conftest import run, simulated_set

HEREDITARY = "diagnosis.terms=[solid_relaxation,pore_pressure_relaxation,power_law_rheology]"
QUICK = ("optim.hybrid.regularisations=[1.0e-2]", "optim.hybrid.iterations=10", HEREDITARY)
PERMEABILITY = Experiment().permeability


def named(diagnosis) -> list[tuple[str, str]]:
    return [(entry["term"], entry["confidence"]) for entry in diagnosis["left_out"]]


def test_a_power_law_on_four_speeds_is_named_with_its_exponent_and_k(tmp_path, coarse_cache):
    folder = simulated_set(tmp_path / "set", effects={"power_law_rheology": {"alpha": 0.1}})
    d = run(folder, coarse_cache, tmp_path / "run", *QUICK).diagnosis
    assert named(d) == [("power_law_rheology", "strong")]
    assert d["left_out"][0]["params"]["alpha"] == pytest.approx(0.1, rel=0.1)
    assert d["permeability"]["corrected"] == pytest.approx(PERMEABILITY, rel=0.05, abs=0)
    assert d["permeability"]["base"] < 0.6 * PERMEABILITY  # what the base model makes of a power law


@pytest.mark.parametrize(
    ("term", "values"),
    [
        ("power_law_rheology", {"alpha": 0.1}),
        # The other two are in make discover-bench (rheology suite) and here with -m slow.
        pytest.param("solid_relaxation", {"g": 0.2, "tau": 0.5}, marks=pytest.mark.slow),
        pytest.param("pore_pressure_relaxation", {"M": 3.0e4}, marks=pytest.mark.slow),
    ],
)
def test_with_a_hold_each_hereditary_term_claims_only_its_own_data(term, values, tmp_path, coarse_cache):
    folder = simulated_set(tmp_path / "set", effects={term: values}, holds=(Hold(2.0e-6, 0.5, 4e-6),))
    d = run(folder, coarse_cache, tmp_path / "run", *QUICK).diagnosis
    assert named(d) == [(term, "strong")]
    assert d["permeability"]["corrected"] == pytest.approx(PERMEABILITY, rel=0.05, abs=0)


def test_a_weak_power_law_on_a_soft_set_leaves_k_unfixed_and_proposes_the_experiment(tmp_path, coarse_cache):
    truth = Experiment(**SOFT_CANTILEVER, effects={"power_law_rheology": {"alpha": 0.03}})
    write_recordings(tmp_path / "set", *simulate(truth))
    d = run(tmp_path / "set", coarse_cache, tmp_path / "run", *QUICK).diagnosis
    assert all(confidence == "weak" for _, confidence in named(d))
    groups = [g for g in d["confounded"] if "power_law_rheology" in g["terms"]]
    assert groups and all("next_experiment" in g for g in groups)
    low, high = d["permeability"]["corrected_interval"]
    assert low <= truth.permeability <= high
    assert "K is not fixed by these data" in d["mismatch"]["summary"]
