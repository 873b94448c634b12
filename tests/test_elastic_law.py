"""The elastic law read off the reference curve, against the Hertz truth."""

import numpy as np
import pytest
import torch

import ptwin
from ptwin.data.recordings import load_recordings, write_recordings
from ptwin.data.simulator import Experiment, simulate
from ptwin.physics.elastic import ReferenceElasticLaw, hertz_force
from ptwin.physics.kinematics import curve_kinematics

pytestmark = pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    experiment = Experiment(base_speeds=(2e-6, 40e-6), samples=1500, noise_std=3e-10)
    folder = tmp_path_factory.mktemp("set")
    write_recordings(folder, *simulate(experiment))
    return experiment, curve_kinematics(load_recordings(folder))[0]


def test_self_consistent_law_recovers_hertz_and_the_paper_variant_does_not(reference, basis_file):
    e, curve = reference
    fluid = ptwin.FluidForce.load(basis_file, permeability=e.permeability, viscosity=e.fluid_viscosity)
    depth = torch.linspace(0.5e-6, 3.5e-6, 50, dtype=torch.float64)
    hertz = torch.from_numpy(hertz_force(depth.numpy(), e.effective_modulus, e.probe_radius))
    args = (curve, e.probe_radius, e.sample_thickness)
    with torch.no_grad():
        consistent = ReferenceElasticLaw(*args, fluid=fluid)(depth) - hertz
        paper = ReferenceElasticLaw(*args, fluid=None)(depth) - hertz
    # The 2 µm/s curve's own Darcy force is tens of nN: the paper's law carries it, ours removes it.
    assert consistent.abs().max() < e.noise_std
    assert paper.min() > 0 and paper.mean() > 5 * consistent.abs().max()
    assert paper[-1] > 10 * consistent.abs().max()  # the bias grows with depth, as R³


def test_law_is_monotone_and_differentiable_in_permeability(reference, basis_file):
    e, curve = reference
    fluid = ptwin.FluidForce.load(basis_file, permeability=e.permeability, viscosity=e.fluid_viscosity)
    law = ReferenceElasticLaw(curve, e.probe_radius, e.sample_thickness, fluid=fluid)
    depth = torch.linspace(0.0, 3.6e-6, 400, dtype=torch.float64)
    force = law(depth)
    assert np.all(np.diff(law.reference_force.numpy()) >= 0)
    (gradient,) = torch.autograd.grad(force[-1], fluid.log_permeability)
    # F_el = F_ref − F_D with F_D ∝ 1/K: dF_el/dlogK = +F_D > 0.
    assert gradient.item() > 0
