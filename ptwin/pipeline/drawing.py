"""Figures drawn aside (``ptwin.aside``) while the run goes on; the lines their drawing said are said by the run
when it takes them, so its output reads as if they were drawn in place."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

from ptwin.aside import Aside

Say = Callable[[str], None]


class Drawing:
    """``start(draw)`` runs ``draw(say)`` → {name: its PNG file} aside, where a fork may be made (``fork``);
    ``figures(progress)`` waits for them ({} where none was started) and says through ``progress`` what ``draw``
    said. Leave it as a context manager: drawing still going when the caller fails is stopped."""

    def __init__(self):
        self._aside: Aside | None = None

    def start(self, draw: Callable[[Say], dict], fork: bool = True) -> None:
        self._aside = Aside(partial(_said, draw), fork=fork)

    def figures(self, progress: Say) -> dict:
        if self._aside is None:
            return {}
        figures, lines = self._aside.result()
        for line in lines:
            progress(line)
        return figures

    def __enter__(self) -> Drawing:
        return self

    def __exit__(self, *exc) -> None:
        if self._aside is not None:
            self._aside.__exit__(*exc)


def _said(draw: Callable[[Say], dict]) -> tuple[dict, list[str]]:
    """(what ``draw`` returns, the lines it said)."""
    lines = []
    return draw(lines.append), lines
