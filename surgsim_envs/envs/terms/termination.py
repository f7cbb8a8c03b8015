"""Termination terms: each declared once as ``fn(env) -> bool``; the episode terminates when any
is true after the step's state update. ``info`` carries nothing extra: a task reports what ended
the episode in its own info keys (e.g. ``dropped``, ``success``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable


@dataclass(frozen=True)
class TerminationTerm:
    """``name`` and ``fn(env) -> bool`` (True: the episode ends this step), ``doc`` when."""

    name: str
    fn: Callable[[Any], bool]
    doc: str = ""


def any_terminated(terms, env) -> bool:
    """True if any of ``terms`` says the episode ends (each is evaluated, in order)."""
    done = False
    for t in terms:
        if t.fn(env):
            done = True
    return done
