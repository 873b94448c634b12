"""The range of the noise's κ² over which the first fits' decisions go the same way, and the fits read under another
κ² within it (``ptwin.fitting.inflation_range``, ``PhysicsFit.under``)."""

import math
from dataclasses import replace

import pytest

from ptwin.diagnosis.diagnose import first_fits
from ptwin.fitting.inflation_range import InflationRange, decided, recorded
from ptwin.fitting.physics_fit import _fixed_within_onset
from ptwin.pipeline.prepare import prepare
from ptwin.pipeline.run import candidate_settings
from tests.conftest import settings_for, simulated_set


def quiet(_: str) -> None:
    pass


def test_a_decision_narrows_the_range_to_its_side_of_its_threshold():
    with recorded() as span:
        decided(2.0, 5.0, below=True)  # κ² 2 below a threshold of 5
        decided(2.0, 0.5, below=False)  # above 0.5
        decided(2.0, -1.0, below=False)  # no positive threshold: the same either way
        decided(2.0, math.inf, below=True)
    assert (span.low, span.high) == (0.5, 5.0)
    assert span.holds(4.9) and not span.holds(5.0) and not span.holds(0.5)
    decided(2.0, 3.0, below=True)  # nothing records outside ``recorded``
    assert (span.low, span.high) == (0.5, 5.0)


def test_a_decision_whose_arithmetic_disagrees_with_its_threshold_leaves_no_range():
    with recorded() as span:
        decided(2.0, 2.0, below=True)  # at the threshold to the last bit, the decision said below
    assert not span.holds(2.0) and not span.holds(1.9) and not span.holds(2.1)


@pytest.mark.parametrize(
    "std, correction, reach",
    [(20e-9, 10e-9, 30e-9), (20e-9, 60e-9, 30e-9), (40e-9, 10e-9, 30e-9), (20e-9, -45e-9, 30e-9)],
)
def test_a_freed_contacts_decision_holds_over_its_range_and_turns_at_its_ends(std, correction, reach):
    # The standard error scales with κ, so the decision at κ² 2 holds for every κ² of its range, and where it
    # kept the correction free it turns just past either finite end.
    inflation = 2.0

    def kept(at: float) -> bool:
        return _fixed_within_onset(std * math.sqrt(at / inflation), correction, reach, at)

    with recorded() as span:
        first = kept(inflation)
    assert span.holds(inflation)
    inside = [span.low * 1.001, span.high * 0.999 if math.isfinite(span.high) else 100.0, inflation * 0.999]
    assert all(kept(at) == first for at in inside if span.holds(at))
    if first:
        assert all(kept(end) != first for end in (span.low * 0.999, span.high * 1.001) if 0 < end < math.inf)


def test_the_intersection_of_two_ranges_is_their_common_part():
    both = InflationRange(0.5, 4.0) & InflationRange(1.0, math.inf)
    assert (both.low, both.high) == (1.0, 4.0)


@pytest.fixture(scope="module")
def estimated(tmp_path_factory, coarse_cache):
    # contacts estimated (the reference's correction freed or held, a held one moved), a viscosity whose √w force
    # moves it, and terms that do nothing on these curves: each kind of decision that reads κ²
    folder = simulated_set(
        tmp_path_factory.mktemp("estimated"),
        effects={"solid_viscosity": {"gamma": 3.0}},
        contact_point="estimate",
        contact_error=1e-7,
    )
    settings = settings_for(f"data.path={folder}", "pgd=coarse", f"cache_dir={coarse_cache}")
    return settings, prepare(settings, quiet)


def test_first_fits_read_under_a_noise_within_their_range_are_the_fits_made_under_it(estimated):
    settings, prepared = estimated
    terms, _ = candidate_settings(prepared, settings)
    iterations = settings.optim.physics_fit.iterations

    def fitted(inflation: float, fits=None):
        samples = replace(prepared.samples, noise_inflation=inflation)
        reference = prepared.make_model.reference
        return first_fits(
            prepared.make_model, samples, prepared.split, terms, iterations, prepared.noise, reference, fits, quiet
        )

    with recorded() as span:
        first = fitted(1.0)
    assert span.holds(1.0) and (span.low > 0 or math.isfinite(span.high))  # some decision read κ²
    # as near either end as the range allows
    for inflation in (span.high * 0.99 if math.isfinite(span.high) else 8.0, max(span.low * 1.01, 1 / 8)):
        read = {subset: c.fit.under(inflation) for subset, c in first.candidates.items() if c.fit is not None}
        again = fitted(inflation)
        for subset, fit in read.items():
            made = again.candidates[subset].fit
            assert (made.chi_square, made.params, made.reference_free) == (
                fit.chi_square,
                fit.params,
                fit.reference_free,
            )
            assert (made.degenerate, made.violations, made.inflation) == (fit.degenerate, fit.violations, inflation)
            assert fit.permeability_std == pytest.approx(made.permeability_std, rel=1e-12, abs=0)
            for term, stds in made.param_std.items():
                assert fit.param_std[term] == pytest.approx(stds, rel=1e-12, abs=0)
