"""One vocabulary for checking outside input: config fields, reset options, CLI flags, scenario
values and file headers.

Every check returns the value in its canonical Python type or raises :class:`ConfigError` (a
ValueError) whose message names the value, the bound it broke and the fix. Numbers are SI; the
``unit`` argument only labels the message. Booleans are never accepted as numbers (``True`` is not
a count of 1), and NaN or inf never pass a range check.

Upper bounds on work: a duration, step count, node count or frame rate that the machine cannot
finish in reasonable time is refused up front rather than run for hours. The limits below are the
package-wide defaults; a caller with a tighter physical bound passes its own ``hi``.
"""

from __future__ import annotations

import math
import numbers
import os
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from surgsim_envs.errors import ConfigError

#: physics steps one call may ask for in one go (settle, hold, a whole episode's substeps): 10^7
#: steps of the cheapest task are minutes of CPU; more is a typo or an attack, not an experiment
MAX_PHYSICS_STEPS = 10_000_000
#: s of simulated time one run may ask for (a teleop script, a material hold, a scenario phase):
#: one hour at the tasks' 1 ms physics step is 3.6 million steps
MAX_SIM_SECONDS = 3600.0
#: Hz, the fastest real-time loop a command may pace (a haptic servo runs at 1 kHz)
MAX_RATE_HZ = 10_000.0
#: nodes a generated mesh may have: 10^7 nodes of float64 positions, velocities and forces are
#: about 1 GB before any solver state
MAX_NODES = 10_000_000


def short_repr(value: Any) -> str:
    """``repr(value)`` cut to 80 characters, for error messages (a 400-digit int stays readable)."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _label(name: str, value: Any, unit: str) -> str:
    return f"{name}={short_repr(value)}" + (f" {unit}" if unit else "")


def _hint(fix: str) -> str:
    return f"; {fix}" if fix else ""


def is_real_number(value: Any) -> bool:
    """True for int / float / numpy real scalars (0-d real arrays included: the library's own
    vectorised arithmetic passes them), False for bool, complex, strings and arrays with entries.
    Configs refuse 0-d arrays where they are given (:func:`config_value`)."""
    if isinstance(value, np.ndarray):
        return value.ndim == 0 and value.dtype.kind in "fiu"
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def real(value: Any, name: str, *, lo: float = -math.inf, hi: float = math.inf, unit: str = "",
         fix: str = "", lo_open: bool = False, hi_open: bool = False) -> float:
    """``value`` as a finite float in [lo, hi] (``lo_open`` / ``hi_open``: exclusive bound)."""
    if not is_real_number(value):
        raise ConfigError(f"{_label(name, value, unit)} must be a real number (int or float), not "
                          f"{type(value).__name__}{_hint(fix)}")
    try:
        v = float(value)
    except OverflowError:
        v = math.inf if value > 0 else -math.inf
    if not math.isfinite(v):
        raise ConfigError(f"{_label(name, value, unit)} must be finite (NaN and inf are refused){_hint(fix)}")
    below = v <= lo if lo_open else v < lo
    above = v >= hi if hi_open else v > hi
    if below or above:
        u = f" {unit}" if unit else ""
        if math.isinf(hi):          # a one-sided bound reads as one
            bound = f"must be {'>' if lo_open else '>='} {lo:g}{u}"
        elif math.isinf(lo):
            bound = f"must be {'<' if hi_open else '<='} {hi:g}{u}"
        else:
            bound = f"is outside {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}{u}"
        raise ConfigError(f"{_label(name, value, unit)} {bound}{_hint(fix)}")
    return v


def positive(value: Any, name: str, *, hi: float = math.inf, unit: str = "", fix: str = "") -> float:
    """``value`` as a finite float > 0 (and <= ``hi``)."""
    return real(value, name, lo=0.0, hi=hi, unit=unit, fix=fix, lo_open=True)


def positives(*, unit: str = "", fix: str = "", **values: Any) -> tuple[float, ...]:
    """Each keyword value as a finite float > 0 (:func:`positive`, named by its keyword), checked
    in the order given: ``positives(radius=r, young=e, fix="SI units")``."""
    return tuple(positive(value, name, unit=unit, fix=fix) for name, value in values.items())


def non_negative(value: Any, name: str, *, hi: float = math.inf, unit: str = "", fix: str = "") -> float:
    """``value`` as a finite float >= 0 (and <= ``hi``)."""
    return real(value, name, lo=0.0, hi=hi, unit=unit, fix=fix)


def weight(value: Any, name: str, *, hi: float = 1e6, fix: str = "") -> float:
    """A reward weight, bonus or cost: a finite float in [0, hi]. The bound keeps a weighted sum of
    a few hundred terms far from float overflow (1e308 * a force is inf, and inf - inf is NaN)."""
    return real(value, name, lo=0.0, hi=hi, fix=fix or f"use a finite number in [0, {hi:g}]")


def integer(value: Any, name: str, *, lo: int | None = None, hi: int | None = None, unit: str = "",
            fix: str = "") -> int:
    """``value`` as an int in [lo, hi]; floats with an integral value are refused (a count is an int)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ConfigError(f"{_label(name, value, unit)} must be an integer, not {type(value).__name__}"
                          f"{_hint(fix)}")
    v = int(value)
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        lo_s = "-inf" if lo is None else f"{lo:,}"
        hi_s = "inf" if hi is None else f"{hi:,}"
        raise ConfigError(f"{_label(name, value, unit)} is outside [{lo_s}, {hi_s}]{_hint(fix)}")
    return v


def steps(value: Any, name: str, *, lo: int = 1, hi: int = MAX_PHYSICS_STEPS, fix: str = "") -> int:
    """A count of physics steps in [lo, hi]; the upper bound keeps one call within minutes of CPU."""
    return integer(value, name, lo=lo, hi=hi, unit="steps",
                   fix=fix or f"at most {hi:,} physics steps run in one call (minutes of CPU); use fewer")


def duration(value: Any, name: str, *, lo: float = 0.0, hi: float = MAX_SIM_SECONDS, lo_open: bool = True,
             fix: str = "") -> float:
    """A simulated or wall-clock duration in s, in (lo, hi]."""
    return real(value, name, lo=lo, hi=hi, unit="s", lo_open=lo_open,
                fix=fix or f"durations longer than {hi:g} s are refused so a run cannot hang for hours")


def rate(value: Any, name: str, *, hi: float = MAX_RATE_HZ, fix: str = "") -> float:
    """A frame or loop rate in Hz, in (0, hi]."""
    return real(value, name, lo=0.0, hi=hi, unit="Hz", lo_open=True,
                fix=fix or f"use a rate in (0, {hi:g}] Hz")


def boolean(value: Any, name: str, fix: str = "") -> bool:
    """``value`` if it is exactly True or False (numpy bools included)."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise ConfigError(f"{name}={short_repr(value)} must be True or False, not {type(value).__name__}{_hint(fix)}")


def choice(value: Any, name: str, options: Iterable[Any], fix: str = "") -> Any:
    """``value`` if it is one of ``options`` (compared by type and value: 5 is not "5")."""
    opts = list(options)
    for o in opts:
        if type(value) is type(o) and value == o:
            return value
    raise ConfigError(f"{name}={short_repr(value)} is not one of {opts}{_hint(fix)}")


def text(value: Any, name: str, fix: str = "") -> str:
    """A non-empty string."""
    if not isinstance(value, str) or not value:
        raise ConfigError(f"{name}={short_repr(value)} must be a non-empty string{_hint(fix)}")
    return value


def path(value: Any, name: str, *, must_exist: bool = True, kind: str = "file", fix: str = "") -> Path:
    """``value`` as a Path (str or os.PathLike); if ``must_exist``, an existing ``kind`` ("file"
    or "dir")."""
    if not isinstance(value, (str, os.PathLike)) or not str(value):
        raise ConfigError(f"{name}={short_repr(value)} must be a path (a non-empty string){_hint(fix)}")
    p = Path(value)
    if must_exist:
        ok = p.is_file() if kind == "file" else p.is_dir()
        if not ok:
            raise ConfigError(f"{name}={str(p)!r} is not an existing {kind}{_hint(fix)}")
    return p


def writable_folder(value: Any, name: str, fix: str = "") -> Path:
    """``value`` as the Path of a folder to write in: created if missing, and it must take a file
    (checked by writing and removing one). Checked before a long command runs, so it cannot fail
    on its output at the end."""
    folder = path(value, name, must_exist=False)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".surgsim-write-check-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise ConfigError(f"{name}={str(folder)!r}: cannot write there ({exc.strerror or exc})"
                          f"{_hint(fix or 'give a writable folder')}") from None
    return folder


def writable_file(value: Any, name: str, fix: str = "") -> Path:
    """``value`` as the Path of a file to be written: not a folder, in a folder
    :func:`writable_folder` accepts."""
    p = path(value, name, must_exist=False)
    if p.is_dir():
        raise ConfigError(f"{name}={str(p)!r} is a folder; give a file path{_hint(fix)}")
    writable_folder(p.parent, f"the folder of {name}={str(p)!r}", fix=fix or "give a path in a writable folder")
    return p


def has_length(value: Any, n: int) -> bool:
    """True if ``value`` is a sequence (not a string, not a 0-d array) of exactly ``n`` entries."""
    if isinstance(value, (str, bytes)) or (isinstance(value, np.ndarray) and value.ndim == 0):
        return False
    try:
        return len(value) == n
    except TypeError:
        return False


def config_value(value: Any, name: str) -> Any:
    """``value`` unchanged, unless it is a 0-d numpy array: a config keeps what it is given, and
    ``round()``, ``len()`` or JSON of a 0-d array fail later, far from the cause."""
    if isinstance(value, np.ndarray) and value.ndim == 0:
        raise ConfigError(f"{name}={short_repr(value)} is a 0-d array; pass the number itself (float(x) or x.item())")
    return value


def name_list(text: Any, name: str, known: Iterable[str], fix: str = "") -> list[str] | None:
    """A comma-separated list of names, each one of ``known`` (None or "" gives None: all); a
    typo is refused by name before a long run, never skipped into an empty result."""
    if text is None or (isinstance(text, str) and not text.strip()):
        return None
    if not isinstance(text, str):
        raise ConfigError(f"{name}={short_repr(text)} must be comma-separated names{_hint(fix)}")
    known = list(known)
    names = [t.strip() for t in text.split(",") if t.strip()]
    unknown = [t for t in names if t not in known]
    if unknown or not names:
        raise ConfigError(f"{name}={text!r}: unknown name(s) {unknown}; choose from {known}{_hint(fix)}")
    return names


def seed(value: Any, name: str = "seed") -> int:
    """A random seed: an integer in [0, 2**63 - 1] (numpy's SeedSequence refuses negatives)."""
    return integer(value, name, lo=0, hi=2**63 - 1, fix="give a non-negative integer seed")


def grid_nodes(extent, spacing: float, what: str, *, hi: int = MAX_NODES, fix: str = "") -> int:
    """The node count of a regular lattice of ``spacing`` m over a box of ``extent`` (3,) m,
    counted before anything is allocated; ConfigError above ``hi``."""
    nodes = 1.0
    for e in extent:
        per_axis = float(e) / float(spacing)          # inf for a denormal spacing: refused below
        nodes *= (math.floor(per_axis) if math.isfinite(per_axis) else per_axis) + 1.0
    if nodes > hi:
        raise ConfigError(f"{what}: a lattice spacing of {spacing:g} m over {[float(e) for e in extent]} m gives about "
                          f"{nodes:.3g} nodes, above the limit of {hi:,}"
                          f"{_hint(fix or 'use a coarser spacing')}")
    return int(nodes)
