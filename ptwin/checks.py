"""A settings dataclass's refusal of a value out of its range, in one line that names the key, what it must be and
what it got (``ptwin.app.typed`` turns it into exit code 2). Below every room: each room's settings use it."""

from __future__ import annotations

from collections.abc import Iterable


def refuse_outside(group: str, settings: object, rules: Iterable[tuple[str, bool, str]]) -> None:
    """``ValueError`` for the first of ``rules`` (key, whether its value is fine, what it must be, with an example)
    that fails: "``group``.key must be …; got …" (``group`` "": a top-level key)."""
    for key, fine, need in rules:
        if not fine:
            raise ValueError(f"{group}{'.' if group else ''}{key} must be {need}; got {getattr(settings, key)}")
