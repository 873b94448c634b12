"""The grading rules, case by case, and their reasons in words."""

import pytest

from ptwin.diagnosis.confidence import HeldOut, grade

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
    ],
)
def test_grade(removal, rivals, implausible, held_out, expected, reason):
    verdict = grade(removal, rivals, implausible, held_out, bic_margin=10.0, heldout_margin=0.1)
    assert verdict.confidence == expected
    if reason is None:
        assert verdict.reasons == []
    else:
        assert any(reason in r for r in verdict.reasons), verdict.reasons
