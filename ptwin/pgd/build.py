"""Build a parametric PGD basis from a ``PGDConfig`` (offline, once)."""

from __future__ import annotations

import resource
import time
from collections.abc import Callable
from contextlib import nullcontext
from functools import partial
from pathlib import Path

import torch

from ptwin.aside import Aside, can_fork
from ptwin.pgd.basis import Basis
from ptwin.pgd.compression import force_amplitudes, force_modes, recompress
from ptwin.pgd.config import PGDConfig
from ptwin.pgd.enrichment import enrich
from ptwin.pgd.problem import build_problem
from ptwin.threads import one_thread


def build_basis(config: PGDConfig, progress: Callable[[str], None] = print) -> Basis:
    """Greedy PGD on the configured mesh (and, with ``richardson``, on the mesh with
    half the rings), then Richardson-combine and recompress the force.

    The pressure field stored is the fine mesh's; the force is the extrapolated one. The two meshes are independent
    problems, each solved on one thread: where a second core is free the coarse mesh is solved beside the fine one
    (``ptwin.aside``), to the same bits, and the build takes the fine mesh's time (pgd=default 1.8–3.0 s against
    3.6–4.8 s one after the other here).
    """
    with one_thread():
        return _build(config, progress)


def _build(config: PGDConfig, progress: Callable[[str], None]) -> Basis:
    _restart_peak_memory()
    start, cpu = time.perf_counter(), time.process_time()
    levels = [config.plane.rings] + ([config.plane.rings // 2] if config.richardson else [])
    weights = [1.0] if not config.richardson else _richardson_weights(config.richardson_order)
    beside = len(levels) > 1 and can_fork()
    peak, cpu_beside = 0, 0.0  # the coarse mesh's own process's, where it had one
    with Aside(partial(_measured, _coarse_force, config, levels[1])) if beside else nullcontext() as forked:
        problem, solution = _solved(config, levels[0], progress)
        forces = [force_modes(solution, problem.dims)]
        if len(levels) > 1:
            (beta, factors), peak, cpu_beside = (
                forked.result() if beside else (_coarse_force(config, levels[1]), 0, 0.0)
            )
            forces.append((beta, factors))
            progress(f"the Richardson mesh ({levels[1]} rings): {beta.numel()} modes")
    betas = [weight * beta for weight, (beta, _) in zip(weights, forces)]
    names = [dim.name for dim in problem.dims.parameters]
    joined = [torch.cat([factors[d] for _, factors in forces], dim=1) for d in range(len(names))]
    force = recompress(names, torch.cat(betas), joined)
    stats = {
        "modes_per_mesh": [beta.numel() for beta in betas],
        "seconds": time.perf_counter() - start,
        "core_seconds": time.process_time() - cpu + cpu_beside,
        "meshes_side_by_side": beside,
        "peak_rss_bytes": max(_peak_memory(), peak),
        "force_ranks": [f.shape[1] for f in force.functions],
    }
    return Basis.from_build(config, problem, solution, force, stats)


def _solved(config: PGDConfig, rings: int, progress: Callable[[str], None]):
    """(the problem on the mesh of ``rings`` rings, its separated solution)."""
    problem = build_problem(config, rings=rings)
    progress(
        f"PGD [{config.coordinates} coordinates] on {problem.dims.plane.size} in-plane x "
        f"{problem.dims.thickness.size} thickness nodes ({rings} rings)"
    )
    return problem, enrich(problem.dims, problem.n_terms, config.enrichment, progress, _force_at_probes(problem))


def _coarse_force(config: PGDConfig, rings: int):
    """(β, parameter factors) of ``force_modes`` on the Richardson mesh of ``rings`` rings, solved as
    ``build_basis`` solves it (one thread)."""
    with one_thread():
        problem, solution = _solved(config, rings, lambda line: None)
        return force_modes(solution, problem.dims)


def _measured(function: Callable, *args):
    """(``function(*args)``, the peak memory [B] and the CPU seconds of this process): a forked process's share."""
    return function(*args), _peak_memory(), time.process_time()


def _peak_memory() -> int:
    """The most memory [B] this process has held (since ``_restart_peak_memory``)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _restart_peak_memory() -> None:
    """Linux: reset the RSS high-water mark so that the peak reported is this build's,
    not that of whatever ran before it in the process (a bench, a test session)."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        pass


def _force_at_probes(problem, count: int = 64, seed: int = 0):
    """The force at fixed random grid points of the parameter box: the output whose
    change per mode is the stopping residual."""
    generator = torch.Generator().manual_seed(seed)
    index = [torch.randint(dim.size, (count,), generator=generator) for dim in problem.dims.parameters]

    def output(factors, amplitudes):
        plane, thickness, *parameters = factors  # in the order of ``Dimensions``
        beta = force_amplitudes(amplitudes, plane, thickness, problem.dims.plane.load)
        return (beta * torch.stack([p[i] for p, i in zip(parameters, index)]).prod(dim=0)).sum(dim=1)

    return output


def _richardson_weights(order: float) -> list[float]:
    """F = (2^p F_h − F_2h)/(2^p − 1): weights of the fine and the coarse force."""
    ratio = 2.0**order
    return [ratio / (ratio - 1), -1 / (ratio - 1)]
