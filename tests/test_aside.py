"""Work done aside (``ptwin.aside``): in a forked child, its value or its exception back as the caller's own; in
the caller where a fork is not safe; a child stopped when the caller leaves without its result."""

import os
import pickle
import time

import pytest
import torch

from ptwin.aside import Aside, can_fork
from ptwin.fitting.lm import FitError
from ptwin.threads import one_thread
from tests.conftest import NO_FORK


def test_the_value_is_computed_in_a_child_and_comes_back_whole(forking):
    caller = os.getpid()
    weights = torch.linspace(0.0, 1.0, 1000, dtype=torch.float64).exp()
    with Aside(lambda: (os.getpid(), {"weights": weights})) as aside:
        assert aside.forked
        child, value = aside.result()
    assert child != caller
    assert torch.equal(value["weights"], weights)


def test_an_exception_in_the_child_is_raised_in_the_caller_with_the_childs_traceback(forking):
    def fails():
        raise FitError("the model cannot be evaluated (K off the grid)")

    with Aside(fails) as aside, pytest.raises(FitError, match="K off the grid") as raised:
        aside.result()
    assert any("in the process working aside" in note and "fails" in note for note in raised.value.__notes__)


class Located(ValueError):
    def __init__(self, message: str, point: int):
        super().__init__(f"{message} at point {point}")


class Holding(ValueError):
    def __init__(self, message: str):
        super().__init__(message)
        self.callback = lambda: None  # a local function: no pickle


def test_an_exception_that_does_not_pickle_back_comes_back_in_words(forking):
    # Located pickles but would not unpickle (its __init__ takes other arguments than it keeps), except where a
    # library made every exception pickle by its attributes (Dask's tblib, in a test process that ran a map).
    def fails(error):
        def raising():
            raise error

        return raising

    try:
        survives = isinstance(pickle.loads(pickle.dumps(Located("off the grid", 7))), Located)
    except TypeError:
        survives = False
    expected = (
        (Located, "off the grid at point 7") if survives else (RuntimeError, r"Located \(off the grid at point 7\)")
    )
    with Aside(fails(Located("off the grid", 7))) as aside, pytest.raises(expected[0], match=expected[1]):
        aside.result()
    with Aside(fails(Holding("a callback"))) as aside, pytest.raises(RuntimeError, match=r"Holding \(a callback\)"):
        aside.result()


def test_a_child_that_dies_without_an_answer_is_said_so(forking):
    with Aside(lambda: os._exit(3)) as aside, pytest.raises(RuntimeError, match="ended with exit code 3"):
        aside.result()


def test_a_child_whose_result_is_never_asked_for_is_stopped_when_the_caller_leaves(forking):
    started = time.perf_counter()
    with pytest.raises(KeyError), Aside(lambda: time.sleep(60)) as aside:
        raise KeyError("the caller failed meanwhile")
    assert not aside._child.is_alive()
    assert time.perf_counter() - started < 30


@pytest.mark.parametrize("why", ["fork=False", "outside one thread"])
def test_without_a_fork_the_function_runs_in_the_caller_once_when_first_asked_for(why, two_threads):
    calls = []
    aside = Aside(lambda: calls.append(os.getpid()) or len(calls), fork=why != "fork=False")
    assert not aside.forked and calls == []
    assert aside.result() == 1 and aside.result() == 1
    assert calls == [os.getpid()]


def test_a_machine_with_an_accelerator_does_not_fork(forking, monkeypatch):
    # with a GPU in the machine autograd's engine starts a thread for it at the first backward pass, and a child
    # forked after that refuses its own ("Unable to handle autograd's threading in combination with fork-based
    # multiprocessing": train.py device=cpu on a lent H200); no GPU here, so the count is told
    monkeypatch.setattr(torch.accelerator, "device_count", lambda: 1)
    aside = Aside(os.getpid)
    assert not aside.forked and aside.result() == os.getpid()


def test_a_child_forked_within_one_thread_runs_torch_after_its_parent_ran_on_two(two_threads):
    # libgomp is not fork-safe: forked on two threads from a process that had run a team of two, a child's log10
    # (MKL's, threaded) waits forever at a barrier for threads that live only in the parent (tried: still waiting
    # after 20 s); forked within one thread it runs. can_fork refuses the first.
    values = torch.rand(4_000_000, dtype=torch.float64, generator=torch.Generator().manual_seed(0)) + 1.0
    values.log10()  # a team of two threads
    assert not can_fork()
    with one_thread():
        if not can_fork():
            pytest.skip(NO_FORK)
        expected = values.log10().sum().item()
        with Aside(lambda: values.log10().sum().item()) as aside:
            aside._child.join(timeout=60)
            assert not aside._child.is_alive(), "the child hangs"
            assert aside.result() == expected
