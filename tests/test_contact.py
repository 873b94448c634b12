"""Estimated contact points and baselines against the simulator's known recording errors."""

import numpy as np
import pytest

from ptwin.data.contact import estimate_baseline
from ptwin.synth.presets import SOFT_CANTILEVER
from ptwin.synth.simulator import Experiment, simulate

pytestmark = pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")


@pytest.mark.parametrize(("spring_constant", "tilt"), [(0.088, 5e-4), (2.88, 0.0), (0.088, -1e-3)])
def test_contact_offset_and_tilt_are_found(spring_constant, tilt):
    setting = {**SOFT_CANTILEVER, "base_speeds": (5e-6,), "noise_correlation": 0.2, "contact_error": 2e-7}
    experiment = Experiment(**{**setting, "spring_constant": spring_constant, "tilt": tilt, "baseline_offset": 3e-10})
    _, curves = simulate(experiment)
    artefacts = np.random.default_rng([0, 1])
    _, offset, error = artefacts.standard_normal(3)  # the simulator's draws: stiffness, offset, contact
    z, force = curves["z"].to_numpy(), curves["force"].to_numpy()
    baseline = estimate_baseline(z, force, spring_constant)
    assert baseline.contact_z == pytest.approx(2e-7 * error, abs=10e-9)
    assert baseline.tilt == pytest.approx(tilt, abs=5e-5)
    assert baseline.offset == pytest.approx(3e-10 * offset + tilt * (baseline.contact_z - 2e-7 * error), abs=1e-11)
    travel, corrected = baseline.remove(z, force)
    assert np.abs(corrected[travel < -0.3e-6]).mean() < 2e-11  # the baseline is gone: noise is left
