"""Is there a display for the interactive MuJoCo viewer? Ask before opening it.

``mujoco.viewer`` initialises GLFW in C; without a display MuJoCo's error handler EXITS the
Python process ("ERROR: could not initialize GLFW", exit status 1), which no ``try`` can catch.
:func:`require_display` checks first, from Python: a DISPLAY / WAYLAND_DISPLAY on Linux and a
successful ``glfw.init()`` (which returns False instead of exiting), and raises
:class:`~surgsim_envs.errors.RenderingUnavailableError` naming the fix otherwise.
"""

from __future__ import annotations

import os
import sys

from surgsim_envs.errors import RenderingUnavailableError

_HINT = ("run under a display (or a virtual one: `xvfb-run -a ...` with MUJOCO_GL unset or 'glfw'), "
         "or render offscreen instead (render_mode='rgb_array', --out DIR)")


def display_problem() -> str | None:
    """Why the interactive viewer cannot open here, or None if it can."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return "no display: the DISPLAY (or WAYLAND_DISPLAY) environment variable is not set"
    try:
        import glfw
    except ImportError:  # pragma: no cover - glfw comes with mujoco
        return "the glfw package (used by mujoco.viewer) is not installed"
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            ok = bool(glfw.init())
        except Exception as exc:  # pragma: no cover - library missing
            return f"GLFW could not start ({exc})"
    if not ok:
        return f"GLFW could not open the display {os.environ.get('DISPLAY', '')!r}"
    return None


def require_display(what: str = "the MuJoCo viewer") -> None:
    """Raise RenderingUnavailableError (never exit) if ``what`` cannot open a window here."""
    problem = display_problem()
    if problem is not None:
        raise RenderingUnavailableError(f"{what} needs a display: {problem}; {_HINT}")
