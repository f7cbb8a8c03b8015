"""Import MuJoCo whatever ``MUJOCO_GL`` says, and say clearly what rendering needs.

``import mujoco`` loads the OpenGL backend that ``MUJOCO_GL`` names (``egl``, ``osmesa``,
``glx``/``glfw``) at import time; a backend whose system library is missing made the import itself
fail with a raw traceback from PyOpenGL (e.g. ``MUJOCO_GL=osmesa`` without libOSMesa:
``'NoneType' object has no attribute 'glGetError'``), even for runs that render nothing
(``surgsim demo --no-video``). :func:`import_mujoco` catches that, records what failed
(:func:`gl_problem`: the backend, the Debian/Ubuntu package that provides it and the
alternatives) and imports MuJoCo again with ``MUJOCO_GL=disable``: physics, forces and plots work,
and creating a renderer raises :class:`~surgsim_envs.errors.RenderingUnavailableError` with that
message (scene/render.py).
"""

from __future__ import annotations

import os
import sys

#: the Debian/Ubuntu package that provides each MuJoCo OpenGL backend's library
BACKEND_PACKAGES = {"egl": "libegl1", "osmesa": "libosmesa6", "glx": "libgl1", "glfw": "libgl1 libglfw3"}
#: the headless backends to suggest instead
ALTERNATIVES = {"egl": "MUJOCO_GL=egl (apt-get install libegl1; no GPU or display needed)",
                "osmesa": "MUJOCO_GL=osmesa (apt-get install libosmesa6; software, slower)"}
NO_RENDERING = "run without rendering (`surgsim demo --no-video`, render_mode=None)"

#: why the requested backend failed to load (None: it loaded, or MuJoCo is not imported yet)
GL_IMPORT_ERROR: str | None = None


def gl_problem(backend: str, exc: BaseException) -> str:
    """The message for a backend that failed to load: names it, its package and the fix."""
    name = backend.lower().strip()
    pkg = BACKEND_PACKAGES.get(name)
    if pkg is None:
        need = f"MUJOCO_GL={backend!r} is not a backend MuJoCo knows on {sys.platform} ({', '.join(BACKEND_PACKAGES)})"
    else:
        need = f"install its library (Debian/Ubuntu: apt-get install {pkg})"
    others = [text for key, text in ALTERNATIVES.items() if key != name]
    return (f"MuJoCo could not load the OpenGL backend MUJOCO_GL={backend!r} ({type(exc).__name__}: {exc}); "
            f"to render, {need}, or use {' or '.join(others)}; or {NO_RENDERING}")


def _purge() -> None:
    for name in [n for n in sys.modules if n.split(".")[0] in ("mujoco", "OpenGL")]:
        del sys.modules[name]


def import_mujoco():
    """``import mujoco``; if the backend ``MUJOCO_GL`` names cannot load, record why
    (:data:`GL_IMPORT_ERROR`) and import MuJoCo without OpenGL instead. Raises the original error
    if MuJoCo cannot be imported even then (not an OpenGL problem)."""
    global GL_IMPORT_ERROR
    if "mujoco" in sys.modules:
        return sys.modules["mujoco"]
    try:
        import mujoco
        return mujoco
    except Exception as exc:  # noqa: BLE001 - PyOpenGL fails with AttributeError, OSError, RuntimeError...
        backend = os.environ.get("MUJOCO_GL", "")
        if not backend.strip():
            raise
        problem = gl_problem(backend, exc)
        _purge()
        os.environ["MUJOCO_GL"] = "disable"
        try:
            import mujoco
        except Exception:
            os.environ["MUJOCO_GL"] = backend
            raise exc from None
        os.environ["MUJOCO_GL"] = backend          # what the user asked for, for the messages
        GL_IMPORT_ERROR = problem
        return mujoco
