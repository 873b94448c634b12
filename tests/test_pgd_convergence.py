"""Observed orders of the two FE discretisations (slope of log error vs log h)."""

import numpy as np

from ptwin.pgd.problem import build_problem
from ptwin.pgd.reference import discrete_force_coefficient, force_coefficient
from tests.conftest import small_config


def observed_order(sizes, errors):
    return np.polyfit(np.log(sizes), np.log(np.abs(errors)), 1)[0]


def test_in_plane_order_is_two_on_edge_graded_discs():
    x = np.array([1.0, 50.0])
    rings = [4, 8, 16]
    errors = []
    for n in rings:
        config = small_config()
        config.plane.rings, config.thickness.nodes = n, 400
        errors.append(discrete_force_coefficient(build_problem(config), x) / force_coefficient(x) - 1)
    for column in range(len(x)):
        order = observed_order(1.0 / np.array(rings), [e[column] for e in errors])
        assert abs(order - 2.0) < 0.15, order


def test_thickness_order_is_two_on_the_graded_mesh():
    x = np.array([1.0])
    config = small_config()
    config.plane.rings = 4
    config.thickness.nodes = 6400
    reference = discrete_force_coefficient(build_problem(config), x)
    counts = [50, 100, 200]
    errors = []
    for n in counts:
        config.thickness.nodes = n
        errors.append((discrete_force_coefficient(build_problem(config), x) / reference - 1)[0])
    assert abs(observed_order(1.0 / np.array(counts), errors) - 2.0) < 0.2


def test_the_cache_key_ignores_the_grid_of_the_other_coordinates():
    from ptwin.pgd.config import Grid

    scaled = small_config()
    assert small_config(height=Grid(1e-6, 1e-3, 7)).hash() == scaled.hash()
    assert small_config(aspect_ratio=Grid(0.2, 1e5, 121)).hash() != scaled.hash()
    paper = small_config(coordinates="paper")
    assert small_config(coordinates="paper", height=Grid(1e-6, 1e-3, 7)).hash() != paper.hash()


def test_a_basis_is_the_same_whatever_the_thread_count_it_is_built_on():
    # The greedy enrichment follows every rounding of its sums: built on two threads and on one, this coarse
    # configuration gave [68, 63] and [67, 61] modes. A cached basis must not depend on the machine's cores.
    import torch

    from ptwin.pgd.build import build_basis

    threads = torch.get_num_threads()
    bases = []
    try:
        for count in (2, 1):
            torch.set_num_threads(count)
            bases.append(build_basis(small_config(), progress=lambda line: None))
    finally:
        torch.set_num_threads(threads)
    assert bases[0].stats["modes_per_mesh"] == bases[1].stats["modes_per_mesh"]
    assert all(torch.equal(a, b) for a, b in zip(bases[0].force.functions, bases[1].force.functions))
    assert torch.get_num_threads() == threads  # the build gave the caller's threads back


def test_the_richardson_mesh_solved_in_a_second_process_gives_the_basis_of_one_process(forking, monkeypatch):
    # Where a second core is free, build_basis solves the coarse Richardson mesh in a forked process beside the
    # fine one; the basis must be the one a single process builds, to the bit (a cached basis names no machine).
    import torch

    from ptwin.pgd import build

    config = small_config(richardson=True)
    beside = build.build_basis(config, progress=lambda line: None)
    assert beside.stats["meshes_side_by_side"]
    monkeypatch.setattr(build, "can_fork", lambda: False)
    alone = build.build_basis(config, progress=lambda line: None)
    assert beside.stats["modes_per_mesh"] == alone.stats["modes_per_mesh"]
    assert len(alone.stats["modes_per_mesh"]) == 2
    assert all(torch.equal(a, b) for a, b in zip(beside.force.functions, alone.force.functions))
    assert torch.equal(beside.force.core, alone.force.core)
