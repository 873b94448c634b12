"""The grading rules, case by case, and their reasons in words."""

import pytest

from ptwin.diagnosis.confidence import FoldFailed, HeldOut, grade

GOOD = HeldOut(gain=2.0, spread={"t.p": 0.1}, folds=4)


@pytest.mark.parametrize(
    ("removal", "rivals", "implausible", "held_out", "expected", "reason"),
    [
        (500.0, [], None, GOOD, "strong", None),
        (15.0, [], None, GOOD, "moderate", "costs only 15 BIC"),
        (500.0, [], None, None, "moderate", "too few curves"),
        (500.0, [], None, HeldOut(2.0, {"t.p": 0.9}, 4), "moderate", "changes between curves (t.p by 90%)"),
        (500.0, ["other"], None, GOOD, "weak", "explain as well with other"),
        (500.0, [], "p = 99 is outside [0, 50]", GOOD, "weak", "outside"),
        (500.0, [], None, HeldOut(1.02, {"t.p": 0.1}, 4), "weak", "improves the prediction by only 2%"),
        (15.0, [], None, None, "weak", "too few curves"),
        (500.0, [], None, FoldFailed("the fit without curve 'v1' failed: off the grid"), "weak", "could not be tested"),
    ],
)
def test_grade(removal, rivals, implausible, held_out, expected, reason):
    verdict = grade(removal, rivals, implausible, held_out, bic_margin=10.0, heldout_margin=0.1)
    assert verdict.confidence == expected
    if reason is None:
        assert verdict.reasons == []
    else:
        assert any(reason in r for r in verdict.reasons), verdict.reasons


def test_a_term_whose_interval_reaches_where_it_does_nothing_is_weak():
    # Real PAAm A as recorded: gamma 1.6 named on its shape and on the samples before contact, but its profile
    # interval (every nuisance refitted with it) is [0, 2.28]: the data do not exclude that it is absent.
    verdict = grade(500.0, [], None, GOOD, bic_margin=10.0, heldout_margin=0.1, absent_within=["gamma = 0"])
    assert verdict.confidence == "weak"
    assert any("reaches gamma = 0, where it does nothing" in r for r in verdict.reasons)


def test_a_term_named_beside_unexplained_structure_is_weak_and_says_why():
    # Real agarose A with 5 Pa·s added: the viscosity passes the BIC margin and the held-out test on the validation
    # samples, but leaves structure no term explains; its γ is what it takes in a model that misses the data.
    left = "whiteness 30.8 against 5.7, what noise alone exceeds one time in 100"
    verdict = grade(500.0, [], None, GOOD, bic_margin=10.0, heldout_margin=0.1, unexplained=left)
    assert verdict.confidence == "weak"
    assert any(f"no term of the vocabulary explains ({left})" in r for r in verdict.reasons)


@pytest.mark.parametrize(
    ("term", "name", "interval", "allowed"),
    [
        ("solid_viscosity", "gamma", [0.0, 2.28], True),  # the low side at the physical bound, where γ = 0
        ("solid_viscosity", "gamma", [None, 2.28], True),
        ("solid_viscosity", "gamma", [0.4, 2.28], False),
        ("pore_pressure_relaxation", "M", [2.1e4, None], True),  # open towards M → ∞, where the lag vanishes
        ("pore_pressure_relaxation", "M", [2.1e4, 4.0e4], False),
        ("solid_relaxation", "tau", [None, None], False),  # no one tau removes the relaxation: g says it
        ("contact_offset", "delta", [-3e-9, 2e-9], True),
    ],
)
def test_where_an_interval_allows_a_terms_absence(term, name, interval, allowed):
    from ptwin.physics.terms import VOCABULARY

    assert VOCABULARY[term].PARAMS[name].allows_absence(interval) is allowed


def test_a_held_out_gain_short_of_its_margin_reads_short_of_it():
    # discover-bench's loop "strain perm. vs base, soft" at seed 3, third round: the strain-dependent K named weak,
    # "on curves left out of the fit it predicts 1.10× better … improves the prediction by only 10% (needs 10%)".
    from ptwin.diagnosis.words import short_of, times_better

    verdict = grade(410.0, [], None, HeldOut(1.0996, {"t.p": 0.1}, 4), bic_margin=10.0, heldout_margin=0.1)
    assert verdict.confidence == "weak"
    assert "on curves left out of the fit it improves the prediction by only 9.96% (needs 10%)" in verdict.reasons
    assert times_better(1.0996, 1.1) == "1.0996× better" and times_better(1.0996) == "1.10× better"
    assert times_better(1.2, 1.1) == "1.20× better" and short_of(9.4, 10.0, 0) == "9"  # where it reads short already
    assert short_of(9.999999999, 10.0, 0) == "9.999999"  # as many decimals as it takes, up to six more
