"""The discovery bench grades a null as the shared bench-sets do: "unexplained" where noise alone is left is a
false alarm; where the setting leaves structure no term has (replicates of differing stiffness), it is right. A drag
concealed where the contact is estimated may be removed with the baselines or named, as the shared p08 names it."""

from bench.discover_bench import Case, verdict
from ptwin.synth.simulator import Experiment


def diagnosis(unexplained: bool, named: tuple[str, ...] = ()) -> dict:
    left_out = [{"term": term, "confidence": "weak"} for term in named]
    return {"left_out": left_out, "unexplained": unexplained, "confounded": []}


def test_unexplained_is_a_false_alarm_on_noise_alone():
    null = Case("null")
    assert verdict(null, Experiment(), diagnosis(False))
    assert not verdict(null, Experiment(), diagnosis(True))
    assert not verdict(null, Experiment(), diagnosis(False, ("solid_viscosity",)))


def test_unexplained_is_right_where_the_setting_leaves_structure():
    spread = Case("null, spots ±10%", setting={"replicates": 2, "stiffness_spread": 0.1})
    assert verdict(spread, Experiment(), diagnosis(True))
    assert not verdict(spread, Experiment(), diagnosis(True, ("solid_viscosity",)))


def test_a_drag_concealed_beside_estimated_contacts_may_go_with_the_baselines_or_be_named():
    drag = Case("drag, estimated", {"cantilever_drag": {"b": 1e-4}}, {"contact_point": "estimate"})
    estimated = Experiment(contact_point="estimate")
    assert verdict(drag, estimated, diagnosis(False))
    assert verdict(drag, estimated, diagnosis(False, ("cantilever_drag",)))
    assert not verdict(drag, estimated, diagnosis(False, ("solid_viscosity",)))
    assert not verdict(Case("null, estimated"), estimated, diagnosis(False, ("cantilever_drag",)))
