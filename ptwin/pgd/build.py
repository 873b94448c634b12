"""Build a parametric PGD basis from a ``PGDConfig`` (offline, once)."""

from __future__ import annotations

import resource
import time
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path

import threadpoolctl
import torch

from ptwin.pgd.basis import Basis
from ptwin.pgd.compression import force_amplitudes, force_modes, recompress
from ptwin.pgd.config import PGDConfig
from ptwin.pgd.enrichment import enrich
from ptwin.pgd.problem import build_problem


def build_basis(config: PGDConfig, progress: Callable[[str], None] = print) -> Basis:
    """Greedy PGD on the configured mesh (and, with ``richardson``, on the mesh with
    half the rings), then Richardson-combine and recompress the force.

    The pressure field stored is the fine mesh's; the force is the extrapolated one.
    """
    with _one_thread():
        return _build(config, progress)


@contextmanager
def _one_thread():
    """torch and the BLAS under numpy on one thread while a basis is built: the greedy enrichment follows every
    rounding of its sums, so the same configuration built on two threads and on one gave different bases ([75, 63]
    modes against [71, 68]; the demo's base-model whiteness 1505 against 739, the same verdict). A cached basis is
    then the same whatever the machine's thread count, and the build no slower (1.8–1.9 s either way)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with threadpoolctl.threadpool_limits(limits=1):
            yield
    finally:
        torch.set_num_threads(threads)


def _build(config: PGDConfig, progress: Callable[[str], None]) -> Basis:
    _restart_peak_memory()
    start = time.perf_counter()
    levels = [config.plane.rings] + ([config.plane.rings // 2] if config.richardson else [])
    weights = [1.0] if not config.richardson else _richardson_weights(config.richardson_order)
    betas, parameters, fine = [], [], None
    for rings, weight in zip(levels, weights):
        problem = build_problem(config, rings=rings)
        progress(
            f"PGD [{config.coordinates} coordinates] on {problem.dims.plane.size} in-plane x "
            f"{problem.dims.thickness.size} thickness nodes ({rings} rings)"
        )
        solution = enrich(problem.dims, problem.n_terms, config.enrichment, progress, _force_at_probes(problem))
        beta, factors = force_modes(solution, problem.dims)
        betas.append(weight * beta)
        parameters.append(factors)
        fine = fine or (problem, solution)
    names = [dim.name for dim in fine[0].dims.parameters]
    joined = [torch.cat([p[d] for p in parameters], dim=1) for d in range(len(names))]
    force = recompress(names, torch.cat(betas), joined)
    stats = {
        "modes_per_mesh": [beta.numel() for beta in betas],
        "seconds": time.perf_counter() - start,
        "peak_rss_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
        "force_ranks": [f.shape[1] for f in force.functions],
    }
    return Basis.from_build(config, fine[0], fine[1], force, stats)


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
