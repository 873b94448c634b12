"""Work done aside (``ptwin.aside``): in a forked child, its value or its exception back as the caller's own; in
the caller where a fork is not safe; a child stopped when the caller leaves without its result."""

import os
import sys
import time

import pytest
import torch

import ptwin.aside
from ptwin.aside import Aside
from ptwin.fitting.lm import FitError


@pytest.fixture
def forking(monkeypatch):
    """Forks as after ``one_thread_for_good``. The test process may have run OpenMP teams of more threads, so the
    children here run no torch kernel: they return what the parent made, or raise, or die."""
    if not sys.platform.startswith("linux"):
        pytest.skip("fork is used on Linux only")
    monkeypatch.setattr(ptwin.aside, "on_one_thread_for_good", lambda: True)


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


def test_an_exception_that_does_not_pickle_back_comes_back_in_words(forking):
    def fails():
        raise Located("off the grid", 7)

    with Aside(fails) as aside, pytest.raises(RuntimeError, match=r"Located \(off the grid at point 7\)"):
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


@pytest.mark.parametrize("why", ["fork=False", "numerics on more threads before"])
def test_without_a_fork_the_function_runs_in_the_caller_once_when_first_asked_for(why):
    # this test process never called one_thread_for_good
    calls = []
    aside = Aside(lambda: calls.append(os.getpid()) or len(calls), fork=why != "fork=False")
    assert not aside.forked and calls == []
    assert aside.result() == 1 and aside.result() == 1
    assert calls == [os.getpid()]
