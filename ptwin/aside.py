"""Work done aside: a function run in a forked child process while the caller goes on, its result fetched when
first asked for.

Why: ptwin's numerics run on one thread (``ptwin.threads``), so a run on one set leaves the second core of a
2-core machine idle, and work that does not depend on the caller's can take it: the hybrid twin trains while the
diagnosis fits its first candidates (``ptwin.pipeline.run``), a basis's coarse Richardson mesh is solved beside
its fine one (``ptwin.pgd.build``). A thread would share the interpreter's lock with the caller (the demo's twin
and first fits in 2.0 s on two threads, 1.3 s forked, 2.5 s one after the other). A fork, not a pool: the child
starts with everything the caller holds (torch imported, the samples prepared), nothing pickled on the way in; the
result comes back pickled through a pipe (plain ``pickle``: torch's own reductions for processes would share
tensors through file descriptors that end with the child).

It forks only from within one thread (``ptwin.threads.one_thread``), which the child keeps: an OpenMP team of more
than one thread, opened in a child forked from a process that had run one, waits forever on a barrier for threads
that live only in the parent (libgomp is not fork-safe: a twin forked outside one thread, in a test process that had
run on two, hung so in MKL's log10). And only where a second core is there to take the work, on Linux (macOS' system
libraries refuse a forked child), outside a daemonic process (a Dask worker), which may have no children, and where
torch sees no accelerator: with a GPU in the machine, autograd's engine starts a thread for it at the first backward
pass, even with ``device=cpu``, and a child forked after that refuses a backward pass of its own (``train.py`` on a
machine with a GPU failed so), nor could it use CUDA again. Anywhere else the function runs in the caller when its
result is first asked for: the same result, later.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import sys
import traceback
from collections.abc import Callable
from typing import Generic, TypeVar

import torch

from ptwin.threads import on_one_thread

T = TypeVar("T")


def can_fork() -> bool:
    """Whether ``Aside`` runs its function in a child here, rather than in the caller when asked."""
    return (
        sys.platform.startswith("linux")
        and len(os.sched_getaffinity(0)) > 1
        and on_one_thread()
        and not multiprocessing.current_process().daemon
        and torch.accelerator.device_count() == 0
    )


class Aside(Generic[T]):
    """``function()`` started in a forked child (``fork``, where ``can_fork``); ``result()`` waits for its value,
    or raises what it raised (its traceback in the child added as a note). Used as a context manager, a child
    whose result was never asked for is stopped on the way out (the caller failed)."""

    def __init__(self, function: Callable[[], T], fork: bool = True):
        self._function, self._child, self._pipe = function, None, None
        self._outcome: tuple[bool, T] | None = None
        if fork and can_fork():
            context = multiprocessing.get_context("fork")
            self._pipe, sending = context.Pipe(duplex=False)
            self._child = context.Process(target=_serve, args=(function, sending), daemon=True)
            self._child.start()
            sending.close()

    @property
    def forked(self) -> bool:
        return self._child is not None

    def result(self) -> T:
        if self._outcome is None:
            self._outcome = self._fetched() if self.forked else (True, self._function())
        done, value = self._outcome
        if not done:
            raise value
        return value

    def _fetched(self) -> tuple[bool, T]:
        try:
            message = self._pipe.recv_bytes()
        except EOFError:  # the child died before it could answer (killed, out of memory)
            message = None
        finally:
            self._pipe.close()
            self._child.join()
        if message is None:
            return False, RuntimeError(f"the process working aside ended with exit code {self._child.exitcode}")
        return pickle.loads(message)

    def __enter__(self) -> Aside[T]:
        return self

    def __exit__(self, *exc) -> None:
        if self.forked and self._child.is_alive():
            self._child.terminate()
            self._child.join()


def _serve(function: Callable[[], T], sending) -> None:
    """In the child: (True, the value) or (False, the exception) sent back pickled."""
    try:
        done, value = True, function()
    except BaseException as error:  # everything goes back to the caller, who raises it as its own
        error.add_note(f"in the process working aside:\n{traceback.format_exc()}")
        done, value = False, error
    try:
        message = pickle.dumps((done, value))
        if not done:  # an exception whose __init__ takes other arguments than it keeps does not come back
            pickle.loads(message)
    except Exception as error:  # what does not come back as itself comes back in words
        what = "its result" if done else f"{type(value).__name__} ({value})"
        message = pickle.dumps((False, RuntimeError(f"the work done aside gave {what}, which did not pickle: {error}")))
    sending.send_bytes(message)
    sending.close()
