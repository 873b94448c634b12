"""The real-noise benches give each curve of a set its own stretch of the records: two curves recorded one after
another never carry one noise."""

from dataclasses import replace

import numpy as np
import pytest

from bench.real_noise import RECORDED_STD, with_real_noise
from ptwin.synth.simulator import Experiment, simulate

SET = Experiment(base_speeds=(2e-6, 8e-6, 32e-6), samples=200, noise_std=RECORDED_STD)


def test_no_two_curves_share_a_sample_of_a_record():
    # Two records with room for three windows wherever the first ones fall, each sample's value its own: the noise a
    # curve got names the samples it came from.
    records = [np.arange(700.0) + 1.0, np.arange(300.0) + 1001.0]
    for seed in range(3):
        noisy = with_real_noise(replace(SET, seed=seed), records)[1]
        clean = simulate(replace(SET, seed=seed, noise_std=0.0))[1]
        drawn = {c: set(np.round((noisy.force - clean.force)[noisy.curve == c], 6)) for c in noisy.curve}
        assert all(len(values) == 200 for values in drawn.values())
        assert len(set.union(*drawn.values())) == 3 * 200, f"seed {seed}: two curves share noise"


def test_records_without_room_for_every_curve_are_refused_in_one_line():
    with pytest.raises(ValueError, match="no noise record has 200 samples left"):
        with_real_noise(SET, [np.arange(450.0)])
