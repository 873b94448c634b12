"""Where the spots of a map run: in this process (``serial``), on a Dask ``LocalCluster`` (``local``: one
single-threaded worker process per core), or on any running Dask scheduler given by its address (a
cluster started by dask-jobqueue on SLURM/PBS, or on Kubernetes), without a change of code.

Results come back to this process, which writes them: the workers need no shared disk. Each task runs
torch on one thread (the workers are the parallelism) and finds the PGD basis in its process's memory
after its first spot (``ptwin.pgd.cache``).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from functools import partial

from ptwin.checks import first_line
from ptwin.heap import keep_heap
from ptwin.threads import one_thread

SERIAL, LOCAL = "serial", "local"
CONNECT_SECONDS = 10


class EngineError(ValueError):
    """An engine that cannot be reached or started; the message names the setting and the fix."""


def _single_threaded(function: Callable, item):
    keep_heap()  # Dask's nannies set glibc's trim threshold, which freezes its mmap threshold (ptwin.heap)
    with one_thread():
        return function(item)


def run_each(
    function: Callable, items: Sequence, scheduler: str = LOCAL, workers: int = 0, failed: Callable | None = None
) -> Iterator[tuple[object, object]]:
    """(item, function(item)) for every item, as each completes. ``failed(item, error)`` gives the result of
    an item whose task was lost (a worker killed, say); without it the error is raised."""
    if scheduler == SERIAL:
        for item in items:
            yield item, _single_threaded(function, item)
        return
    yield from _on_dask(function, items, scheduler, workers, failed)


@contextmanager
def _dask_quiet() -> Iterator[None]:
    """Dask's loggers at WARNING while a map runs on it: its INFO lines (a scheduler starting, nannies, connections:
    some thirty a map, under a face's logging) broke into the progress bar and said nothing a user acts on; its
    warnings and errors still show."""
    logger = logging.getLogger("distributed")
    level = logger.level
    logger.setLevel(max(logger.getEffectiveLevel(), logging.WARNING))
    try:
        yield
    finally:
        logger.setLevel(level)


def _on_dask(function: Callable, items: Sequence, scheduler: str, workers: int, failed: Callable | None):
    """``run_each`` on Dask: a ``LocalCluster`` of this machine's cores, or the scheduler at ``scheduler``."""
    import dask  # only maps import Dask
    from distributed import Client, LocalCluster, as_completed  # its import sets its loggers' levels: quieted after

    with _dask_quiet():
        if scheduler == LOCAL:
            # No dashboard shows the workers' statistical profiles, whose sampler takes the GIL every 10 ms. The
            # scheduler's HTTP server (health, metrics) runs without one, on Dask's dashboard port 8787 unless told:
            # a free port on this machine, so that a second map or a notebook's cluster is no "port in use" warning.
            with dask.config.set({"distributed.worker.profile.enabled": False}):
                cluster = LocalCluster(
                    n_workers=workers or os.cpu_count() or 1,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                    scheduler_kwargs={"dashboard": False, "dashboard_address": "localhost:0"},
                )
            client = Client(cluster)
        else:
            try:
                cluster, client = None, Client(scheduler, timeout=CONNECT_SECONDS)
            except (OSError, ValueError, TypeError) as error:
                raise EngineError(
                    f"map.scheduler={scheduler}: no Dask scheduler answers there ({first_line(error)}); "
                    f"start one (dask scheduler, dask-jobqueue) and give its address, or use map.scheduler=local"
                ) from None
        try:
            task = partial(_single_threaded, function)
            futures = client.map(task, list(items), pure=False)
            item_of = {future.key: item for future, item in zip(futures, items)}
            for future in as_completed(futures):
                item = item_of[future.key]
                try:
                    yield item, future.result()
                except Exception as error:
                    if failed is None:
                        raise
                    yield item, failed(item, error)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
