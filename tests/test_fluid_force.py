"""The FluidForce layer: derivatives, out-of-range policy, basis I/O."""

import pytest
import torch

import ptwin
from ptwin import files
from ptwin.pgd.basis import FORMAT, Basis, BasisError
from ptwin.pgd.build import build_basis
from ptwin.pgd.config import Grid
from ptwin.pgd.reference import force_coefficient
from ptwin.physics.fluid_accuracy import closed_form_error
from tests.conftest import small_config


def test_gradcheck_in_velocity_radius_height_and_permeability(basis_file):
    layer = ptwin.FluidForce.load(basis_file, permeability=2e-16, viscosity=1e-3)
    inputs = [
        torch.tensor([1e-5, 4e-5], dtype=torch.float64, requires_grad=True),
        torch.tensor([2e-6, 7e-6], dtype=torch.float64, requires_grad=True),
        torch.tensor([6e-3, 3e-5], dtype=torch.float64, requires_grad=True),
        torch.tensor(2e-16, dtype=torch.float64, requires_grad=True),
    ]
    # Scale to O(1) so finite differences resolve every input.
    scales = [1e-5, 1e-6, 1e-5, 1e-16]

    def scaled(u, r, h, k):
        return layer.evaluate(u * scales[0], r * scales[1], h * scales[2], k * scales[3]) * 1e6

    unit = [(t / s).detach().requires_grad_(True) for t, s in zip(inputs, scales)]
    assert layer._separable_prefactor is not None  # the fused law is what is checked
    assert torch.autograd.gradcheck(scaled, unit, check_forward_ad=True)


def test_fused_law_equals_the_generic_separated_sum(basis_file):
    # Same basis, two evaluation paths: the fused node and the autograd chain through
    # each 1-D function. Values, backward gradients and torch.func Jacobians agree.
    fused = ptwin.FluidForce.load(basis_file, permeability=2e-16, viscosity=1e-3)
    generic = ptwin.FluidForce.load(basis_file, permeability=2e-16, viscosity=1e-3)
    generic._separable_prefactor = None
    generator = torch.Generator().manual_seed(1)
    velocity = 10 ** (torch.rand(300, generator=generator, dtype=torch.float64) * 4 - 8)
    radius = 10 ** (torch.rand(300, generator=generator, dtype=torch.float64) * 2.5 - 7.5)  # some below the grid
    height = radius * 10 ** (torch.rand(300, generator=generator, dtype=torch.float64) * 4)

    def forces(layer, theta):
        return layer.evaluate(velocity * theta[0], radius * theta[1], height * theta[2], 2e-16 * theta[3])

    theta = torch.ones(4, dtype=torch.float64)
    values = [forces(layer, theta) for layer in (fused, generic)]
    assert torch.allclose(values[0], values[1], rtol=1e-12, atol=0)
    jacobians = [torch.func.jacfwd(lambda t, layer=layer: forces(layer, t))(theta) for layer in (fused, generic)]
    assert torch.allclose(jacobians[0], jacobians[1], rtol=1e-10, atol=1e-30)
    gradients = [
        torch.autograd.grad(forces(layer, theta.requires_grad_(True)).sum(), theta)[0] for layer in (fused, generic)
    ]
    assert torch.allclose(gradients[0], gradients[1], rtol=1e-10, atol=0)


def test_derivative_in_permeability_is_minus_force_over_permeability(basis_file):
    layer = ptwin.FluidForce.load(basis_file, permeability=3e-16, viscosity=1e-3)
    velocity = torch.tensor([2e-6, 8e-5], dtype=torch.float64)
    radius = torch.tensor([1e-6, 6e-6], dtype=torch.float64)
    force = layer(velocity, radius, torch.full_like(radius, 6e-3))
    (gradient,) = torch.autograd.grad(force.sum(), layer.log_permeability)
    # d/dlogK = K d/dK = −F (F ∝ 1/K exactly).
    assert gradient.item() == pytest.approx(-force.sum().item(), rel=1e-6)


def test_a_layer_at_another_permeability_shares_the_tables_and_owns_its_k(basis_file):
    layer = ptwin.FluidForce.load(basis_file, permeability=3e-16, viscosity=1e-3)
    other = layer.at(5e-16)
    fresh = ptwin.FluidForce.load(basis_file, permeability=5e-16, viscosity=1e-3)
    assert other.functions is layer.functions and other.viscosity == layer.viscosity
    velocity = torch.tensor([2e-6, 8e-5], dtype=torch.float64)
    radius = torch.tensor([1e-6, 6e-6], dtype=torch.float64)
    height = torch.full_like(radius, 6e-3)
    assert torch.equal(other(velocity, radius, height), fresh(velocity, radius, height))
    with torch.no_grad():
        other.log_permeability += 1.0
    assert layer.permeability.item() == pytest.approx(3e-16, rel=1e-14, abs=0)


def test_first_contact_follows_the_small_radius_law(basis_file):
    layer = ptwin.FluidForce.load(basis_file, permeability=2e-16, viscosity=1e-3)
    radius = torch.tensor([0.0, 1e-9, 3e-8], dtype=torch.float64)
    force = layer(torch.full_like(radius, 1e-5), radius, torch.full_like(radius, 6e-3))
    closed = force_coefficient(1e4) * 1e-3 * 1e-5 * radius**3 / 2e-16
    assert force[0] == 0
    # The law's a³ to the digits; its coefficient within what the basis states of itself (``closed_form_error``:
    # 1.6% for the tests' small basis, which is 1.36% under the closed form here; the default basis 0.02%).
    # torch.allclose's default atol of 1e-8 N let any force of these sizes pass.
    assert (force[2] / force[1]).item() == pytest.approx(30.0**3, rel=1e-6)
    assert torch.allclose(force[1:], closed[1:], rtol=closed_form_error(layer.basis), atol=0)


def test_point_off_the_grid_is_refused_with_the_fix(basis_file):
    layer = ptwin.FluidForce.load(basis_file)
    with pytest.raises(ValueError, match="aspect_ratio .* below the basis grid .* pgd.aspect_ratio.minimum"):
        layer(torch.tensor([1e-5]), torch.tensor([1e-5]), torch.tensor([1e-7]))


def test_save_load_round_trip_is_bit_exact(small_basis, basis_file, tmp_path):
    loaded = Basis.load(basis_file)
    assert loaded.config_hash == small_basis.config_hash
    for a, b in zip(loaded.force.functions, small_basis.force.functions):
        assert torch.equal(a, b)
    assert torch.equal(loaded.field["factors_aspect_ratio"], small_basis.field["factors_aspect_ratio"])


def test_corrupted_truncated_and_foreign_files_are_refused(basis_file, tmp_path):
    data = basis_file.read_bytes()
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(BasisError, match="truncated.pt: checksum mismatch, the file is damaged; rebuild it"):
        Basis.load(truncated)
    payload = files.load(basis_file, FORMAT, "")
    payload["format"] = "ptwin-pgd-basis/0"
    foreign = tmp_path / "foreign.pt"
    files.save(foreign, payload)
    with pytest.raises(BasisError, match="format 'ptwin-pgd-basis/0', this ptwin reads 'ptwin-pgd-basis/2'"):
        Basis.load(foreign)
    plain = tmp_path / "plain.pt"
    torch.save(payload, plain)  # a file ptwin did not write
    with pytest.raises(BasisError, match="plain.pt: not a ptwin file"):
        Basis.load(plain)


def test_paper_coordinates_contract_the_tucker_core_like_einsum():
    # The paper's R × H separation leaves R and H of rank > 1: the general Tucker path
    # (its accuracy, which stalls, is shown by `make bench`).
    basis = build_basis(small_config(coordinates="paper", height=Grid(1e-6, 1e-2, 41)), progress=lambda line: None)
    layer = ptwin.FluidForce(basis, permeability=2e-16, viscosity=1e-3)
    assert layer.core.numel() > 1 and layer._separable_prefactor is None
    generator = torch.Generator().manual_seed(2)
    velocity = 10 ** (torch.rand(50, generator=generator, dtype=torch.float64) * 4 - 8)
    radius = 10 ** (torch.rand(50, generator=generator, dtype=torch.float64) * 2 - 7)
    height = 10 ** (torch.rand(50, generator=generator, dtype=torch.float64) * 3 - 5)
    permeability = torch.tensor(2e-16, dtype=torch.float64)
    factors = [
        layer.functions["velocity"](velocity),
        layer.functions["permeability"](permeability.reshape(1)).expand(50, -1),
        layer.functions["contact_radius"](radius),
        layer.functions["height"](height),
    ]
    expected = 1e-3 * torch.einsum("abcd,na,nb,nc,nd->n", layer.core, *factors)
    assert torch.allclose(layer(velocity, radius, height), expected, rtol=1e-12, atol=0)
