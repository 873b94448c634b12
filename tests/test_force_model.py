"""ForceModel against the forward simulator: two routes to the same recording, term by term."""

import dataclasses
import math

import pytest
import torch

import ptwin
from ptwin.data.kinematics import curve_kinematics
from ptwin.data.recordings import load_recordings
from ptwin.physics.contact import ContactNuisance
from ptwin.physics.elastic import ReferenceCurve
from ptwin.physics.model import ForceModel, smooth_contact_radius
from ptwin.physics.samples import Samples
from tests.conftest import simulated_set

TRUTHS = {
    "solid_viscosity": {"gamma": 5.0},
    "solid_relaxation": {"g": 0.1, "tau": 0.5},
    "pore_pressure_relaxation": {"M": 3.0e4},
    "power_law_rheology": {"alpha": 0.05},
    "strain_dependent_permeability": {"m": 2.0},
    "cantilever_drag": {"b": 1.0e-4},
    "contact_offset": {"delta": 0.1e-6},
}


def model_for(folder, basis_path, terms, values):
    recordings = load_recordings(folder)
    meta = recordings.meta
    curves = curve_kinematics(recordings)
    reference, others = curves[0], curves[1:]
    fluid = ptwin.FluidForce.load(basis_path, permeability=2.0e-16, viscosity=meta.fluid_viscosity)
    model = ForceModel(ReferenceCurve(reference), fluid, meta.probe_radius, meta.sample_thickness, terms, values)
    return model, Samples.from_curves(others)


@pytest.mark.parametrize("term", list(TRUTHS))
def test_each_term_reproduces_the_recording_it_was_concealed_in(term, tmp_path, coarse_cache):
    basis_path = next(coarse_cache.glob("*.pt"))
    folder = simulated_set(
        tmp_path, base_speeds=(0.5e-6, 40e-6), samples=500, noise_std=0.0, effects={term: TRUTHS[term]}
    )
    with_term, samples = model_for(folder, basis_path, (term,), {term: TRUTHS[term]})
    without, _ = model_for(folder, basis_path, (), {})
    use = samples.in_contact
    with torch.no_grad():
        error = (with_term(samples) - samples.force)[use].square().mean().sqrt()
        effect = (without(samples) - samples.force)[use].square().mean().sqrt()
    assert effect > 2e-9  # the term matters here ...
    assert error < 0.1 * effect  # ... and the model with its true parameters accounts for it


def test_one_pass_over_samples_and_nodes_equals_the_elastic_law_first(tmp_path, coarse_cache):
    # components() runs the samples and the reference's depth nodes through the rate forces together; reading
    # the elastic law off the nodes first (elastic_nodes) and the samples' rate forces after must agree, term
    # by term and in order, with contacts corrected on the curves (never on the nodes) and a hereditary term
    # between two direct ones.
    basis_path = next(coarse_cache.glob("*.pt"))
    folder = simulated_set(tmp_path, base_speeds=(0.5e-6, 40e-6), samples=300, noise_std=0.0)
    terms = ("solid_viscosity", "power_law_rheology", "pore_pressure_relaxation", "contact_offset")
    model, samples = model_for(folder, basis_path, terms, {t: TRUTHS[t] for t in terms})
    model.contact = ContactNuisance(samples.curve_ids)
    with torch.no_grad():
        model.contact.offsets.fill_(30e-9)
        one_pass = model.components(samples)
        elastic = model.elastic(model.depth(samples))
        two_passes = {"elastic": elastic, **model.rate_forces(samples, elastic)}
    assert list(one_pass) == list(two_passes) == ["elastic", "fluid", "solid_viscosity", "power_law_rheology"]
    for name, force in two_passes.items():
        torch.testing.assert_close(one_pass[name], force, rtol=1e-12, atol=1e-21)


def test_samples_written_into_after_an_evaluation_are_evaluated_as_they_now_are(tmp_path, coarse_cache):
    # The reference keeps the samples joined with its depth nodes for the samples last seen (a fit evaluates the
    # same ones at every step); samples written into in place are other samples, and must not get the old ones' force.
    basis_path = next(coarse_cache.glob("*.pt"))
    folder = simulated_set(tmp_path, base_speeds=(0.5e-6, 40e-6), samples=300, noise_std=0.0)
    model, samples = model_for(folder, basis_path, ("solid_viscosity",), {"solid_viscosity": {"gamma": 5.0}})
    with torch.no_grad():
        model(samples)
        samples.velocity.mul_(2.0)
        samples.depth.add_(5e-8)
        fresh = dataclasses.replace(samples, depth=samples.depth.clone(), velocity=samples.velocity.clone())
        assert torch.equal(model(samples), model(fresh))


def test_moving_the_reference_correction_leaves_every_other_curves_contact_where_it_was():
    # The other curves' corrections are relative to the reference's: their contacts (offset + reference, what the
    # rate forces see) stay, and only the reference's moves.
    contact = ContactNuisance(("a", "b"))
    with torch.no_grad():
        contact.offsets.copy_(torch.tensor([10e-9, -5e-9], dtype=torch.float64))
        contact.reference.fill_(3e-9)
    contact.move_reference(20e-9)
    assert contact.reference.item() == pytest.approx(20e-9, abs=1e-18)
    torch.testing.assert_close(contact.offsets + contact.reference, torch.tensor([13e-9, -2e-9], dtype=torch.float64))


def test_terms_report_non_physical_values():
    from ptwin.physics.terms import VOCABULARY

    rho = 12e-6
    assert VOCABULARY["solid_viscosity"](rho, gamma=-1.0).violation() == "gamma < 0"
    assert VOCABULARY["contact_offset"](rho, delta=4e-6).violation().startswith("|delta|")
    assert VOCABULARY["pore_pressure_relaxation"](rho, M=1e4).violation() is None


@pytest.mark.parametrize(
    ("delta", "contradicted"),
    [
        (-0.5e-6, True),  # a Hertz solid pushes 22 nN half a micron in: the recording shows its baseline there
        (-20e-9, False),  # 0.18 nN, under 5σ: a contact there is the baseline's to hide
        (20e-9, False),  # the recording is still at its baseline where this contact begins
        (0.3e-6, True),  # it already pushes 0.3 µm past the recorded contact: no contact begins there
    ],
)
def test_a_contact_offset_is_held_to_where_the_recording_says_contact_can_be(delta, contradicted):
    # The elastic law is read off the reference at its recorded depths: a common contact shift changes only the
    # fluid's geometry, and a fit put it 564 nm before the recorded contact in a 300 nm baseline (a drag and a
    # viscosity concealed, known contact), named strong. A Hertz law as read off a recording, noise 0.25 nN.
    from ptwin.physics.elastic import hertz_force
    from ptwin.physics.terms import VOCABULARY

    rho, modulus, noise = 10e-6, 1.5e4, 0.25e-9
    term = VOCABULARY["contact_offset"](rho, delta=delta)
    reason = term.law_violation(lambda depth: hertz_force(depth, modulus, rho), lambda: modulus, noise)
    assert (reason is not None) == contradicted
    if contradicted:
        assert f"delta = {delta * 1e9:.3g} nm" in reason


def test_the_pore_term_says_where_its_force_stops_depending_on_k(tmp_path, coarse_cache):
    # Undrained (relaxation time ≫ the recordings), F_p → M·U·R whatever K is: the note must fire exactly there.
    basis_path = next(coarse_cache.glob("*.pt"))
    folder = simulated_set(tmp_path, base_speeds=(0.5e-6, 40e-6), samples=500, noise_std=0.0)
    name = "pore_pressure_relaxation"
    model, samples = model_for(folder, basis_path, (name,), {name: {"M": 3.0e4}})
    term, use = model.terms[name], samples.in_contact
    radius = smooth_contact_radius(samples.depth, model.probe_radius)[use].max().item()
    duration = max(
        (samples.time[use & (samples.curve == i)].max() - samples.time[use & (samples.curve == i)].min()).item()
        for i in range(len(samples.curve_ids))
    )
    drains_in = model.fluid.viscosity * radius**2 / (3.0e4 * duration)  # K whose relaxation time is the duration

    def fluid(permeability):
        with torch.no_grad():
            model.fluid.log_permeability.fill_(math.log(permeability))
            return model.rate_forces(samples)["fluid"][use]

    def change(permeability):  # relative change of the fluid force when K falls tenfold
        a, b = fluid(permeability), fluid(permeability / 10)
        return ((a - b).norm() / a.norm()).item()

    undrained, drained = drains_in / 100, drains_in * 10
    assert term.permeability_note(undrained, model.fluid.viscosity, radius, duration) is not None
    assert change(undrained) < 0.02
    assert term.permeability_note(drained, model.fluid.viscosity, radius, duration) is None
    assert change(drained) > 0.2


def test_a_law_that_falls_with_depth_is_no_solids_and_its_fit_is_rejected(tmp_path, coarse_cache):
    # A viscosity 10⁵× the field's typical 5 Pa s, subtracted from the reference curve, leaves an elastic law
    # falling with depth: no solid's. The right viscosity leaves it monotone.
    from ptwin.fitting.physics_fit import fit_physics

    basis_path = next(coarse_cache.glob("*.pt"))
    folder = simulated_set(
        tmp_path, base_speeds=(0.5e-6, 40e-6), samples=500, effects={"solid_viscosity": {"gamma": 5.0}}
    )
    right, samples = model_for(folder, basis_path, ("solid_viscosity",), {"solid_viscosity": {"gamma": 5.0}})
    absurd, _ = model_for(folder, basis_path, ("solid_viscosity",), {"solid_viscosity": {"gamma": 5.0e5}})
    assert right.law_fall() <= right.reference.noise_std
    assert absurd.law_fall() > 0.5 * float(absurd.reference.reference_force.max())
    absurd.requires_grad_(False)  # judged as it stands: no parameter fitted but K
    absurd.fluid.log_permeability.requires_grad_(True)
    fit = fit_physics(absurd, samples, torch.nonzero(samples.in_contact).squeeze(1), iterations=0)
    assert "falls by" in fit.violations["solid_viscosity"] and not fit.physical
    assert not fit.settled  # no step taken: the cap, not the fit, ended it
    # A law that falls is each term's reason: a pair's state said it twice ("rejected: … falls by 17.2 nN …; … falls
    # by 17.2 nN …", a pore pair on real agarose).
    fall = fit.violations["solid_viscosity"]
    pair = dataclasses.replace(
        fit, violations={"solid_viscosity": fall, "cantilever_drag": fall, "solid_relaxation": "g < 0"}
    )
    assert pair.why_not_physical == f"{fall}; g < 0"
