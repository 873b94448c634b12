"""Figures drawn aside (``ptwin.pipeline.drawing``): what a drawing said is said when its figures are taken, drawn
in a child or in the caller alike; a drawing never started draws nothing."""

import os

import pytest

from ptwin.pipeline.drawing import Drawing


def _draw(say):
    say("figure b not drawn: no positive finite value to put on a log axis")
    return {"a": os.getpid()}


@pytest.mark.parametrize("aside", [True, False], ids=["forked", "in the caller"])
def test_what_a_drawing_said_is_said_when_its_figures_are_taken(aside, request):
    if aside:
        request.getfixturevalue("forking")
    said = []
    with Drawing() as drawing:
        drawing.start(_draw, fork=aside)
        assert said == []
        figures = drawing.figures(said.append)
    assert (figures["a"] != os.getpid()) == aside
    assert said == ["figure b not drawn: no positive finite value to put on a log axis"]


def test_a_drawing_never_started_draws_nothing():
    with Drawing() as drawing:
        assert drawing.figures(print) == {}
