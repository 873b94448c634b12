"""ptwin's numerics on one thread: torch's and the BLAS's under numpy. Below every room: the PGD build, a diagnosis
and a map's spot each run under it.

Why one: ptwin's tensors are small (a fit's hundreds to thousands of samples, a basis's few hundred modes), so a
second thread costs more than it gives (the warm demo 7.3–7.4 s on two threads, 6.9–7.1 on one, three runs each on
a 2-core machine), and a sum split over threads is rounded differently on machines with other core counts: the same
configuration built on two threads and on one gave different PGD bases ([75, 63] modes against [71, 68]), and the
same recordings diagnosed differ in their last digits. On one thread a result is the same on every machine."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import threadpoolctl
import torch


@contextmanager
def one_thread() -> Iterator[None]:
    """torch and the BLAS under numpy on one thread within, the caller's thread counts given back after."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with threadpoolctl.threadpool_limits(limits=1):
            yield
    finally:
        torch.set_num_threads(threads)


def on_one_thread() -> bool:
    """Whether torch runs on one thread here (within ``one_thread``): then no OpenMP team of more threads opens."""
    return torch.get_num_threads() == 1
