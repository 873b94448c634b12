"""The PGD basis against the closed form, the exact discrete model and the Bessel field."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg
import torch

from ptwin.pgd.build import build_basis
from ptwin.pgd.fem import interval_matrices, triangle_matrices
from ptwin.pgd.mesh import unit_disc
from ptwin.pgd.problem import build_problem, log_grid
from ptwin.pgd.reference import bessel_pressure, discrete_force_coefficient, force_coefficient
from ptwin.physics.fluid_accuracy import verify
from tests.conftest import settings_for, small_config


def test_closed_form_limit_and_thin_film():
    # c(∞) = 4π Σ 1/j_n³ ≈ 1.01639 (physics-terms.md); thin films: c(x) → π/(8x) + O(1).
    assert force_coefficient(1e4) == pytest.approx(1.01639, abs=1e-5)
    x = 1e-3
    assert force_coefficient(x) * x == pytest.approx(np.pi / 8, rel=1e-2)


def test_fast_diagonalisation_equals_sparse_direct_solve():
    config = small_config()
    config.plane.rings, config.thickness.nodes = 3, 30
    problem = build_problem(config)
    # The nodal P1 system, assembled independently of the problem's eigenbasis.
    nodes, triangles, rim = unit_disc(3, config.plane.ring_density, config.plane.edge_grading)
    full_stiffness, full_mass = triangle_matrices(nodes, triangles)
    stiffness, mass = full_stiffness[~rim][:, ~rim], full_mass[~rim][:, ~rim]
    z_stiffness, z_mass = interval_matrices(problem.thickness_nodes)
    x = 2.5
    matrix = x * sp.kron(stiffness, z_mass) + sp.kron(mass, z_stiffness) / x
    top = np.zeros(len(problem.thickness_nodes))
    top[-1] = 1
    load = np.kron(np.asarray(full_mass[~rim].sum(axis=1)).ravel(), top)  # ∫ of each free basis function
    direct = load @ scipy.sparse.linalg.spsolve(matrix.tocsc(), load)
    # Roundoff at the condition number of a φ mesh whose elements span 1e-7 … 0.5.
    assert discrete_force_coefficient(problem, [x])[0] == pytest.approx(direct, rel=1e-8)


def test_small_basis_against_discrete_model_and_closed_form(small_basis):
    report = verify(small_basis, points=1000, discrete_points=4)
    assert report["discrete"] < 1e-3  # the PGD's own error
    # The 6-ring disc extrapolated against 3 rings: its discretisation error is ~1.6e-2.
    assert report["closed_form"] < 2e-2


def test_pressure_field_against_bessel_series(small_basis):
    field, config = small_basis.field, small_basis.config
    grids = [log_grid(getattr(config, name)) for name in ("velocity", "permeability", "contact_radius", "aspect_ratio")]
    picks = [10, 10, 10, 70]  # U, K, R, x at grid nodes (x ≈ 72)
    values = [g[i].item() for g, i in zip(grids, picks)]
    weights = field["amplitudes"].clone()
    for name, i in zip(("velocity", "permeability", "contact_radius", "aspect_ratio"), picks):
        weights = weights * field[f"factors_{name}"][i]
    pgd = (field["factors_plane"] * weights) @ field["factors_thickness"].T  # (plane, thickness)
    velocity, permeability, radius, x = values
    r = field["plane_nodes"].norm(dim=1).numpy()[:, None]
    phi = field["thickness_nodes"].numpy()[None, :]
    away = (r < 0.8) & (phi < 1 - 0.2 / x) & (phi > 1 - 3 / x)  # below the top edge, where P is not negligible
    exact = bessel_pressure(
        r * radius,
        phi * x * radius,
        velocity=velocity,
        permeability=permeability,
        contact_radius=radius,
        height=x * radius,
    )
    difference = (pgd.numpy() - exact)[away]
    assert np.linalg.norm(difference) / np.linalg.norm(exact[away]) < 1e-2


def test_velocity_and_permeability_modes_are_exact_power_laws(small_basis):
    field, config = small_basis.field, small_basis.config
    for name, exponent in (("velocity", 1.0), ("permeability", -1.0), ("contact_radius", 1.0)):
        law = log_grid(getattr(config, name)) ** exponent
        law = law / law.norm()
        factors = field[f"factors_{name}"]
        ratio = factors / (law[:, None] * torch.sign(factors[0]))
        assert (ratio - 1).abs().max() < 1e-8, name


@pytest.mark.slow
@pytest.mark.parametrize(("preset", "closed_form", "discrete"), [("default", 1e-3, 1e-4), ("precise", 1e-4, 1e-5)])
def test_preset_meets_its_tolerances(preset, closed_form, discrete):
    # The precise preset's enrichment stagnated with its late modes' fixed points stopped at 25 iterations:
    # 3.1e-4 from the closed form, 6.9e-5 from the discrete solution. Converged, 4.6e-5 and 1.8e-6.
    report = verify(
        build_basis(settings_for(f"pgd={preset}", "data.path=-", "cache_dir=-").pgd, progress=lambda line: None)
    )
    assert report["closed_form"] <= closed_form
    assert report["discrete"] <= discrete
