"""Offscreen rendering of a :class:`Simulation`; MP4 output (:class:`VideoWriter`, scene/media.py).

Headless machines: set ``MUJOCO_GL=egl`` (Mesa EGL, no GPU needed) or ``MUJOCO_GL=osmesa``
(``apt-get install libosmesa6``) before MuJoCo is imported; :mod:`surgsim_envs.scene` sets
``egl`` by default when there is no display. Where no OpenGL context can be created, creating a
:class:`SceneRenderer` raises :class:`~surgsim_envs.errors.RenderingUnavailableError` with that
advice, and everything else (physics, forces, plots) keeps working.

Tissue surfaces are written into ``d.flexvert_xpos`` by ``sim.sync_visual()`` right before
``Renderer.update_scene`` (MuJoCo's own kinematics would otherwise show the rest shape).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from surgsim_envs.errors import ConfigError, RenderingUnavailableError

_GL_HINT = ("set MUJOCO_GL=egl (Mesa EGL, works without a GPU; apt-get install libegl1) or MUJOCO_GL=osmesa "
            "(apt-get install libosmesa6) before importing mujoco, or run without rendering (e.g. `surgsim demo --no-video`)")


class SceneRenderer:
    """Renders RGB frames (H, W, 3) uint8 of a simulation from its named cameras.

    sim: a Simulation; width, height: pixels (at most the model's offscreen buffer,
    ``SceneConfig.render_width/height``, at least 640x480).
    """

    def __init__(self, sim, width: int = 640, height: int = 480):
        import mujoco

        from surgsim_envs.scene import gl_backend

        if gl_backend.GL_IMPORT_ERROR is not None:     # MuJoCo was imported without OpenGL
            raise RenderingUnavailableError(gl_backend.GL_IMPORT_ERROR)
        m = sim.render_model   # physics model + tissue flexes (scene/visual.py)
        for what, v, cap in (("width", width, m.vis.global_.offwidth), ("height", height, m.vis.global_.offheight)):
            if not isinstance(v, int) or v <= 0 or v > cap:
                raise ConfigError(f"render {what} must be an integer in [1, {cap}] px, got {v!r}; "
                                  "raise SceneConfig.render_width/height for larger frames")
        self.sim = sim
        try:
            self._renderer = mujoco.Renderer(m, height=height, width=width)
        except Exception as exc:  # no GL library, no display, bad MUJOCO_GL, ...
            raise RenderingUnavailableError(
                f"could not create an offscreen OpenGL context (MUJOCO_GL={os.environ.get('MUJOCO_GL', '<unset>')!r}): "
                f"{exc}. To render, {_GL_HINT}.") from exc
        self.width, self.height = width, height
        self.cameras = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_CAMERA, i) for i in range(m.ncam)]

    def render(self, camera: str | int = -1) -> np.ndarray:
        """One RGB frame from ``camera`` (a camera name, an index, or -1 for the free camera)."""
        if isinstance(camera, str) and camera not in self.cameras:
            raise ConfigError(f"unknown camera {camera!r}; cameras in this scene: {self.cameras}")
        data = self.sim.sync_visual()
        self._renderer.update_scene(data, camera=camera)
        return self._renderer.render().copy()

    def close(self) -> None:
        if getattr(self, "_renderer", None) is not None:
            self._renderer.close()
            self._renderer = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):  # pragma: no cover - interpreter shutdown order
        try:
            self.close()
        except Exception:
            pass


# MP4 output lives in scene/media.py (H.264 when imageio-ffmpeg is installed, else mp4v, stated)
from surgsim_envs.scene.media import VideoWriter  # noqa: E402,F401
