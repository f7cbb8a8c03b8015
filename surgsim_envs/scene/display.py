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
import threading

import numpy as np

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


def open_viewer(model, data, *, key_callback=None, panels: bool = False, help_text: tuple[str, str] | None = None,
                camera: str | None = None):
    """``mujoco.viewer.launch_passive`` with MuJoCo's side panels hidden unless ``panels`` (they
    cover about 60 % of a default window; Tab / Shift+Tab still toggle them) and, if given,
    ``help_text`` = (left column, right column) drawn in the window's top-left corner (e.g. a
    device's key bindings); ``camera``: a camera of the model to look through at first (the task's
    render camera), else MuJoCo's free camera. Call :func:`require_display` first."""
    import mujoco
    import mujoco.viewer

    viewer = mujoco.viewer.launch_passive(model, data, key_callback=key_callback, show_left_ui=panels,
                                          show_right_ui=panels)
    if help_text is not None:
        viewer.set_texts((mujoco.mjtFontScale.mjFONTSCALE_100, mujoco.mjtGridPos.mjGRID_TOPLEFT,
                          help_text[0], help_text[1]))
    cam_id = -1 if camera is None else mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
    if cam_id >= 0:       # start from the scene's named camera (the view rgb_array frames); drag to leave it
        with viewer.lock():
            viewer.cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
            viewer.cam.fixedcamid = cam_id
    return viewer


def close_viewer(viewer, timeout: float = 10.0) -> None:
    """Close a ``mujoco.viewer.launch_passive`` handle and WAIT for its window thread to finish.

    ``Handle.close`` only asks the viewer thread (a daemon) to exit. If the interpreter exits
    while that thread is still tearing its window down, the ``glfw.terminate`` registered at exit
    runs under it and the process dies with a segmentation fault (seen with
    ``surgsim teleop ... --device keyboard``). Joining the thread first makes the exit clean."""
    try:
        viewer.close()
    except Exception:  # pragma: no cover - already gone
        pass
    me = threading.current_thread()
    for thread in threading.enumerate():
        if thread is not me and thread.name.endswith("(_launch_internal)"):
            thread.join(timeout)


def frame_tissue(viewer, sim, distance: float | None = None) -> None:
    """Point a passive viewer's free camera at the tissue of ``sim`` (a Simulation), from the
    front and 30 degrees above, at ``distance`` m (default: 3x the tissue's largest extent, at
    least 0.15 m). The viewer's default camera frames the whole floor, where a 5 cm organ is a few
    pixels. The mouse still orbits and zooms from there."""
    pos = sim.tissue().positions
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    if distance is None:
        distance = max(3.0 * float(np.max(hi - lo)), 0.15)
    with viewer.lock():
        viewer.cam.lookat[:] = (0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), hi[2])
        viewer.cam.distance, viewer.cam.azimuth, viewer.cam.elevation = float(distance), 90.0, -30.0
