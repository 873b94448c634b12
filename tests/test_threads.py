"""ptwin's numerics on one thread (``ptwin.threads``): within a build, a diagnosis and a map's spot, and the caller's
thread counts given back after, an error or not."""

from types import SimpleNamespace

import pytest
import threadpoolctl
import torch

from ptwin.threads import one_thread


def counts() -> tuple[int, set[int]]:
    """(torch's threads, the thread counts of the BLAS and OpenMP pools numpy and torch loaded)."""
    return torch.get_num_threads(), {pool["num_threads"] for pool in threadpoolctl.threadpool_info()}


def test_within_one_thread_and_the_callers_after(two_threads):
    with one_thread():
        assert counts() == (1, {1})
    assert torch.get_num_threads() == 2


class Stopped(Exception):
    pass


def stopped(seen: list):
    """A stage that notes what it runs on, then stops the caller."""

    def stage(*args, **kwargs):
        seen.append(counts())
        raise Stopped

    return stage


def test_a_diagnosis_runs_on_one_thread_and_gives_the_callers_back_when_it_fails(two_threads, monkeypatch, tmp_path):
    import ptwin.pipeline.run as chain

    seen = []
    monkeypatch.setattr(chain, "prepare", stopped(seen))  # the chain's first stage
    with pytest.raises(Stopped):
        chain.run(SimpleNamespace(seed=0), tmp_path)
    assert seen == [(1, {1})] and torch.get_num_threads() == 2


@pytest.mark.parametrize("face", ["detection", "detection_limits"])
def test_a_term_added_and_its_ladder_run_on_one_thread(face, two_threads, monkeypatch, tmp_path):
    # python -m ptwin.inject fits the recordings' own strength and each size's ladder outside the diagnoses it runs
    import ptwin.pipeline.inject as inject

    seen = []
    monkeypatch.setattr(inject, "_as_recorded", stopped(seen))  # what either does first
    settings = SimpleNamespace(
        inject=SimpleNamespace(term="solid_viscosity", sizes=[1.0]), diagnosis=SimpleNamespace(terms=[])
    )
    with pytest.raises(Stopped):
        getattr(inject, face)(settings, tmp_path, progress=lambda line: None)
    assert seen == [(1, {1})] and torch.get_num_threads() == 2
