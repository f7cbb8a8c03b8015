"""The outcome of one hostile input, shared by the tests/test_fuzz_*.py suites and
scripts/fuzz_counts.py (the counts table).

Each surface is a function ``case -> result`` that feeds one hostile input to the package.
:func:`outcome` runs it under a per-case timeout (SIGALRM, main thread) and classifies it:

- ``ok``: it worked and everything it returned is finite;
- ``refused``: it raised the project's error (:class:`~surgsim_envs.errors.ConfigError`, a
  ValueError) with a message;
- ``raw``: any other exception (a raw TypeError, IndexError, ... or an empty message);
- ``nan``: it returned NaN or inf somewhere;
- ``hang``: no answer within the timeout.

The tests assert that only ``ok`` and ``refused`` occur; the script counts all five.
"""

from __future__ import annotations

import math
import signal
from typing import Any, Callable

import numpy as np

from surgsim_envs.errors import ConfigError

OUTCOMES = ("ok", "refused", "raw", "nan", "hang")


class _Hang(BaseException):
    """Raised by the alarm handler (a BaseException: no ``except Exception`` swallows it)."""


def non_finite(value: Any, depth: int = 0) -> bool:
    """True if ``value`` (numbers, arrays, dicts, lists, tuples, nested) holds NaN or inf."""
    if depth > 8:
        return False
    if isinstance(value, bool) or value is None or isinstance(value, (str, bytes)):
        return False
    if isinstance(value, (int, np.integer)):
        return False
    if isinstance(value, (float, np.floating)):
        return not math.isfinite(float(value))
    if isinstance(value, np.ndarray):
        return value.dtype.kind in "fc" and not bool(np.all(np.isfinite(value)))
    if isinstance(value, dict):
        return any(non_finite(v, depth + 1) for v in value.values())
    if isinstance(value, (list, tuple)):
        return any(non_finite(v, depth + 1) for v in value)
    return False


def outcome(fn: Callable, *args, timeout_s: float = 30.0) -> tuple[str, str]:
    """``(kind, detail)`` of ``fn(*args)``: kind in :data:`OUTCOMES`; detail the error message."""
    def _alarm(signum, frame):
        raise _Hang

    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout_s)
    try:
        result = fn(*args)
    except _Hang:
        return "hang", f"no answer within {timeout_s:g} s"
    except ConfigError as exc:
        return ("refused", str(exc)) if str(exc).strip() else ("raw", "ConfigError with an empty message")
    except SystemExit as exc:     # argparse: a usage error with its message on stderr, exit code 2
        return ("refused", f"argparse exit {exc.code}") if exc.code == 2 else ("raw", f"SystemExit({exc.code})")
    except Exception as exc:  # noqa: BLE001 - what the fuzz suites look for
        return "raw", f"{type(exc).__name__}: {exc}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    if non_finite(result):
        return "nan", f"non-finite result {result!r}"[:300]
    return "ok", ""


def check(fn: Callable, *args, timeout_s: float = 30.0, names: tuple = ()) -> str:
    """Assert the outcome is ``ok`` or ``refused`` (and, if refused, that the message names one
    of ``names``); return the kind."""
    kind, detail = outcome(fn, *args, timeout_s=timeout_s)
    assert kind in ("ok", "refused"), f"{kind}: {detail} for {args!r}"[:2000]
    if kind == "refused" and names and not detail.startswith("argparse exit"):
        assert any(str(n) in detail for n in names), f"the error does not name any of {names}: {detail}"
    return kind
