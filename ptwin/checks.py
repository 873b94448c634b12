"""A settings object's refusal of a value out of its range, in one line that names the key as the user writes it,
what it must be and what it got (``ptwin.app.typed`` turns it into exit code 2, the synth's options into its exit),
and what any error says, in one line, where a refusal quotes it. Below every room: each room's settings use it."""

from __future__ import annotations

from collections.abc import Callable, Iterable


def refuse_outside(settings: object, rules: Iterable[tuple[str, bool, str]], spelt: Callable[[str], str]) -> None:
    """``ValueError`` for the first of ``rules`` (attribute of ``settings``, whether its value is fine, what it must
    be, with an example) that fails: "<key> must be …; got …", the key as ``spelt`` writes the attribute's name
    (``"optim.hybrid.{}".format`` for a config group, ``str`` at the top level, a command-line option)."""
    for key, fine, need in rules:
        if not fine:
            raise ValueError(f"{spelt(key)} must be {need}; got {getattr(settings, key)}")


def first_line(error: BaseException, silent: str | None = None) -> str:
    """The first line of what ``error`` says; where it says nothing, ``silent`` (default: its type's name). An error
    without a message has no first line: taking it by index raised IndexError in the very place meant to report the
    error (a model raising a bare RuntimeError ended LM's fit so, not in a ``FitError``)."""
    lines = str(error).splitlines()
    if lines:
        return lines[0]
    return type(error).__name__ if silent is None else silent
