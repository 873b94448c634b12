"""The structure test's null distribution: its false-alarm rate on noise alone is the one it states."""

from dataclasses import replace

import numpy as np
import pytest
import torch

from ptwin.data.kinematics import curve_kinematics
from ptwin.data.noise import Drift, NoiseModel, model_inflation
from ptwin.data.recordings import load_recordings, write_recordings
from ptwin.diagnosis.locate import pooled_whiteness
from ptwin.diagnosis.null import MODEL_ERROR, TermEvidence, structure_test
from ptwin.physics.elastic import ReferenceCurve
from ptwin.physics.samples import Samples
from ptwin.synth.simulator import Experiment, correlated_noise, simulate

BLOCK = 50


def flat_samples(curves: int, length: int, std: float, inflation: float) -> Samples:
    n = curves * length
    return Samples(
        time=torch.arange(n, dtype=torch.float64) % length,
        depth=torch.linspace(0, 1e-6, length, dtype=torch.float64).repeat(curves),
        velocity=torch.zeros(n, dtype=torch.float64),
        base_speed=torch.zeros(n, dtype=torch.float64),
        force=torch.zeros(n, dtype=torch.float64),
        start=torch.arange(n) % length == 0,
        curve=torch.arange(n) // length,
        in_contact=torch.ones(n, dtype=torch.bool),
        noise_floor=torch.full((n,), std, dtype=torch.float64),
        curve_ids=tuple(f"v{i}" for i in range(curves)),
        noise_inflation=inflation,
    )


@pytest.mark.parametrize(
    ("share", "memory", "drift"),
    [(0.0, 0.0, 0.0), (0.6, np.exp(-1 / 5), 0.0), (0.0, 0.0, 0.1), (0.6, np.exp(-1 / 5), 0.3)],
)
def test_noise_alone_exceeds_the_threshold_as_often_as_stated(share, memory, drift):
    # Known κ² (ν = ∞), no reference: W of 600 simulated residuals against the stated 10% quantile; where the
    # baselines held a drift (``noise.Drift``: an AR(1) of 300-sample memory, ``drift`` of the variance on top),
    # the residuals carry it and the test simulates it (without it, W of white noise with a drift of 0.1 exceeded
    # white noise's 10% quantile in 600 of 600).
    inflation = max(1.0, model_inflation(share, memory, BLOCK))
    slow = np.exp(-1 / 300)
    noise = NoiseModel(2e-10, share * memory, inflation, 0.0, "known", 0, share, memory)
    noise = replace(noise, drift=Drift(20.0, 3, drift, slow, 0.3) if drift else None)
    samples = flat_samples(3, 1000, 2e-10, inflation)
    index = torch.arange(3000)
    test = structure_test(samples, index, None, noise, BLOCK, 0.1)
    rng = np.random.default_rng(7)
    draws = []
    for _ in range(600):
        parts = [
            np.sqrt(1 - share) * rng.standard_normal(1000)
            + np.sqrt(share) * correlated_noise(rng, 1000, 1.0, memory)
            + correlated_noise(rng, 1000, np.sqrt(drift), slow)
            for _ in range(3)
        ]
        residual = torch.from_numpy(np.concatenate(parts) * 2e-10)
        draws.append(pooled_whiteness(samples, residual, index, BLOCK))
    assert np.mean(np.array(draws) > test.whiteness.quantile(0.1)) == pytest.approx(0.1, abs=0.04)  # binomial sd 0.012
    assert np.mean(draws) == pytest.approx(test.whiteness.scale, rel=0.05)
    # The threshold: the stated quantile, beyond what a tolerated model error adds.
    assert test.threshold == pytest.approx(test.whiteness.quantile(0.1) + BLOCK * MODEL_ERROR**2 / inflation)


def test_the_elastic_laws_own_noise_lifts_what_noise_alone_reads(tmp_path):
    write_recordings(tmp_path, *simulate(Experiment(samples=1000, noise_std=3e-10, base_speeds=(1e-6, 1e-5))))
    reference, fitted = curve_kinematics(load_recordings(tmp_path))
    law = ReferenceCurve(reference)
    samples = Samples.from_curves([fitted])
    index = torch.nonzero(samples.in_contact).squeeze(1)
    white = NoiseModel(3e-10, 0.0, 1.0, 0.0, "known", 0)
    alone = structure_test(samples, index, None, white, BLOCK, 0.01)
    shared = structure_test(samples, index, law, white, BLOCK, 0.01)
    assert alone.whiteness.scale == pytest.approx(1.0, abs=0.15)
    assert shared.whiteness.scale > 1.3  # a block of the curve averages a few dozen of the reference's samples
    # ν blocks of baseline behind κ²: a heavier tail, a higher threshold.
    measured = NoiseModel(3e-10, 0.0, 1.0, 0.0, "known", 0, blocks=8.0)
    assert structure_test(samples, index, law, measured, BLOCK, 0.01).threshold > 1.5 * shared.threshold


def test_a_curve_whose_baseline_drifts_more_than_the_sets_is_judged_by_its_own_inflation(tmp_path):
    # Real noise drifts more on some curves than on others: four curves of white noise and one whose noise is
    # a slow AR(1) (κ² ≈ 15 at 50-sample blocks) throughout, baseline and contact alike. Judged by the set's
    # pooled κ² (1.5 here), that curve's noise alone reads as structure; by its own baseline's, it does not.
    rng = np.random.default_rng(5)
    parts = [rng.standard_normal(1200) for _ in range(4)] + [correlated_noise(rng, 1200, 1.0, 0.9)]
    meta, curves = simulate(Experiment(samples=1200, noise_std=0.0, z_start=-1.0e-6))
    for curve, noise in zip(dict.fromkeys(curves["curve"]), parts):
        curves.loc[curves["curve"] == curve, "force"] += 3e-10 * noise
    write_recordings(tmp_path, meta, curves)
    kinematics = curve_kinematics(load_recordings(tmp_path))
    assert kinematics[-1].noise.inflation > 5.0  # measured on its own baseline
    samples = Samples.from_curves(kinematics, noise_inflation=1.5)
    index = torch.nonzero(samples.in_contact).squeeze(1)
    noise = torch.from_numpy(3e-10 * np.concatenate(parts))[index]
    as_the_set = replace(samples, curve_inflation=torch.full_like(samples.time, 1.5))
    assert pooled_whiteness(as_the_set, noise, index, BLOCK) > 2.0  # its W ≈ 15 / 1.5 lifts the mean of five
    assert pooled_whiteness(samples, noise, index, BLOCK) < 1.0


def _term_draws(test, shape, noise_draws, error=None):
    """TermEvidence of a one-parameter term of ``shape`` (noise units) fitted by least squares to each column of
    ``noise_draws`` (+ a model error ``error``), the smaller model being zero."""
    from ptwin.diagnosis.null import term_evidence

    residuals = noise_draws if error is None else noise_draws + error[:, None]
    gains = (shape @ residuals) ** 2 / (shape @ shape)
    totals = np.sum(residuals**2, axis=0)
    n = shape.size
    return [term_evidence(test, shape, (t, t - g), n, 1, "term", 0.1) for t, g in zip(totals, gains)]


SHARE, MEMORY = 0.6, np.exp(-1 / 5)  # AR(1) noise of 5-sample memory: κ² ≈ 5 along a smooth shape


def _smooth_term_in_ar_noise(rng, replicates):
    """The structure test (α 10%) on three 1000-sample curves of AR(1) noise (``SHARE``, ``MEMORY``), the shape of a
    smooth term (growing with depth and speed) and ``replicates`` draws of that noise, (3000, replicates)."""
    inflation = max(1.0, model_inflation(SHARE, MEMORY, BLOCK))
    noise = NoiseModel(2e-10, SHARE * MEMORY, inflation, 0.0, "known", 0, SHARE, MEMORY)
    samples = flat_samples(3, 1000, 2e-10, inflation)
    test = structure_test(samples, torch.arange(3000), None, noise, BLOCK, 0.1)
    shape = np.sqrt(samples.depth.numpy() / 1e-6) * (1.0 + samples.curve.numpy())
    draws = np.stack(
        [
            np.sqrt(1 - SHARE) * rng.standard_normal(3000) + np.sqrt(SHARE) * correlated_noise(rng, 3000, 1.0, MEMORY)
            for _ in range(replicates)
        ],
        axis=1,
    )
    return test, shape, draws


def test_a_terms_gain_on_noise_alone_is_chi_square_whatever_the_correlation():
    # The gain a smooth term takes off noise alone, over λ along its shape, is χ²(1): mean 1, exceeded by 2.71 one
    # time in ten. Without λ it would be ~5× that.
    test, shape, draws = _smooth_term_in_ar_noise(np.random.default_rng(11), 800)
    evidence = _term_draws(test, shape, draws)
    gains = np.array([e.gain for e in evidence])
    assert evidence[0].inflation == pytest.approx(1 + 2 * SHARE * MEMORY / (1 - MEMORY), rel=0.2)
    assert gains.mean() == pytest.approx(1.0, abs=0.15)  # sd of the mean of 800 χ²(1): 0.05
    assert np.mean(gains > 2.706) == pytest.approx(0.1, abs=0.035)
    # Beyond noise and model error: never on noise alone, nor with a model error of the tolerated size shaped
    # exactly like the term (the worst case); always for a term three times that size.
    assert not any(e.beyond for e in evidence)
    tolerated = MODEL_ERROR * shape / np.sqrt(np.mean(shape**2))
    assert np.mean([e.beyond for e in _term_draws(test, shape, draws, tolerated)]) <= 0.1
    assert all(e.beyond for e in _term_draws(test, shape, draws, 3 * tolerated))


def test_a_pairs_joint_gain_on_noise_alone_is_chi_square_of_two():
    # What diagnose tests a pair by: the two shapes fitted together to noise alone, the gain over λ along what the
    # fit adds (a direction that changes from draw to draw) read against χ²(2): mean 2, exceeded by 4.61 one time in
    # ten, and beyond noise and model error never.
    from ptwin.diagnosis.null import term_evidence

    test, shape, draws = _smooth_term_in_ar_noise(np.random.default_rng(17), 800)
    shapes = np.stack([shape, np.linspace(0.0, 1.0, shape.size) ** 2 * np.sqrt(np.abs(shape))], axis=1)
    fitted = shapes @ np.linalg.lstsq(shapes, draws, rcond=None)[0]  # what the pair adds, per draw
    totals = np.sum(draws**2, axis=0)
    evidence = [
        term_evidence(test, added, (t, t - added @ added), shape.size, 2, "a + b", 0.1)
        for added, t in zip(fitted.T, totals)
    ]
    gains = np.array([e.gain for e in evidence])
    assert gains.mean() == pytest.approx(2.0, abs=0.3)  # sd of the mean of 800 χ²(2): 0.07
    assert np.mean(gains > 4.605) == pytest.approx(0.1, abs=0.04)
    assert not any(e.beyond for e in evidence)


def _held_out_draws(test, shape, noise_draws, validation, error):
    """``HeldOutTest`` evidence of a one-parameter term of ``shape`` (noise units) fitted by least squares on the
    samples outside ``validation`` to each column of ``noise_draws`` + the model error ``error``, the smaller
    model being zero."""
    from types import SimpleNamespace

    from ptwin.diagnosis.name import Candidate, HeldOutTest

    held_out = HeldOutTest(test, validation, 0.1)
    train = ~validation
    smaller_fit, larger_fit = SimpleNamespace(params={}), SimpleNamespace(params={"term": {"size": 1.0}})
    evidence = []
    for column in (noise_draws + error[:, None]).T:
        size = (shape[train] @ column[train]) / (shape[train] @ shape[train])
        smaller = Candidate((), smaller_fit, 1.0, 1.0, residual=column)
        larger = Candidate(("term",), larger_fit, 1.0, 1.0, residual=column - size * shape)
        evidence.append(held_out.evidence(smaller, larger, "term"))
    return evidence


def test_a_terms_held_out_gain_exceeds_noise_and_model_error_at_most_as_often_as_stated():
    # The selection's held-out test (name.HeldOutTest): a smooth term fitted on 85% of the samples, its gain on the
    # other 15% in AR(1) noise. Noise and a tolerated model error shaped like the term (the worst case) pass it at
    # most one time in ten (the stated α); a term three times that size nearly always does (one validation draw
    # of 15% of the samples: 99–100% over seeds).
    rng = np.random.default_rng(13)
    test, shape, draws = _smooth_term_in_ar_noise(rng, 600)
    validation = rng.random(3000) < 0.15
    tolerated = MODEL_ERROR * shape / np.sqrt(np.mean(shape**2))
    assert np.mean([e.beyond for e in _held_out_draws(test, shape, draws, validation, 0 * tolerated)]) <= 0.1
    assert np.mean([e.beyond for e in _held_out_draws(test, shape, draws, validation, tolerated)]) <= 0.1
    assert np.mean([e.beyond for e in _held_out_draws(test, shape, draws, validation, 3 * tolerated)]) >= 0.95


def test_the_held_out_test_with_samples_pinning_contacts_keeps_its_false_alarm_rate():
    # Where contacts are estimated, the held-out test has a second part on the validation samples before contact
    # (name.HeldOutTest.pinning), each part at α/2. One term acting on both (in contact a smooth shape, before it
    # a contact shift's ramp), fitted by least squares on the train samples of both to noise (+ a tolerated model
    # error shaped like it): kept at most α (10%) of the time. A term the contact nuisances absorb in contact (its
    # shape there zero) that is five times the tolerated size before contact (90 validation samples there): kept
    # nearly always (0%, 2.2% and 99% when written).
    from types import SimpleNamespace

    from ptwin.diagnosis.name import Candidate, HeldOutTest

    rng = np.random.default_rng(17)
    test, shape, draws = _smooth_term_in_ar_noise(rng, 400)
    inflation = max(1.0, model_inflation(SHARE, MEMORY, BLOCK))
    noise = NoiseModel(2e-10, SHARE * MEMORY, inflation, 0.0, "known", 0, SHARE, MEMORY)
    before = flat_samples(3, 200, 2e-10, inflation)
    pinning = structure_test(before, torch.arange(600), None, noise, BLOCK, 0.1)
    ramp = np.tile(np.linspace(0.0, 1.0, 200) ** 2, 3)
    pinning_draws = np.stack(
        [
            np.sqrt(1 - SHARE) * rng.standard_normal(600) + np.sqrt(SHARE) * correlated_noise(rng, 600, 1.0, MEMORY)
            for _ in range(400)
        ],
        axis=1,
    )
    validation, pinning_validation = rng.random(3000) < 0.15, rng.random(600) < 0.15
    held_out = HeldOutTest(test, validation, 0.1, pinning, pinning_validation)
    smaller_fit, larger_fit = SimpleNamespace(params={}), SimpleNamespace(params={"term": {"size": 1.0}})

    def kept(contact_shape, pinning_shape, contact_error, pinning_error):
        train = np.concatenate([~validation, ~pinning_validation])
        both = np.concatenate([contact_shape, pinning_shape])
        outcomes = []
        for column in np.concatenate([draws + contact_error[:, None], pinning_draws + pinning_error[:, None]]).T:
            size = (both[train] @ column[train]) / max(both[train] @ both[train], 1e-300)
            smaller = Candidate((), smaller_fit, 1.0, 1.0, residual=column[:3000], pinning=column[3000:])
            larger = Candidate(
                ("term",),
                larger_fit,
                1.0,
                1.0,
                residual=(column - size * both)[:3000],
                pinning=(column - size * both)[3000:],
            )
            outcomes.append(held_out.evidence(smaller, larger, "term").beyond)
        return np.mean(outcomes)

    tolerated, tolerated_before = (MODEL_ERROR * s / np.sqrt(np.mean(s**2)) for s in (shape, ramp))
    assert kept(shape, ramp, 0 * shape, 0 * ramp) <= 0.1
    assert kept(shape, ramp, tolerated, tolerated_before) <= 0.1
    assert kept(0 * shape, ramp, 0 * shape, 5 * tolerated_before) >= 0.95


@pytest.mark.parametrize(
    ("gain", "said"),
    [
        (37.4, "takes 37 units of χ² off"),
        (-0.3, "takes 0 units of χ² off"),
        (-4.2, "adds 4 units of χ² to"),
        (1.2, "takes 1 unit of χ² off"),  # real PAAm, before contact: "takes 1 units"
        (-0.7, "adds 1 unit of χ² to"),
    ],
)
def test_a_terms_gain_is_said_as_what_it_takes_off_or_adds_never_a_negative_or_minus_zero(gain, said):
    # Held-out samples can fit worse with the term (real agarose B: -4 on validation, -0 before contact).
    words = TermEvidence("solid_viscosity", gain, 10.0, 1.0, 0.005).words()
    assert f"solid_viscosity {said} the residual under the noise model" in words
    assert "-" not in words.split("residual")[0]
