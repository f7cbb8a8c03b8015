"""Optional wrappers for the SurgSim tasks.

:class:`PixelObservation` replaces (or augments) the state observation with an RGB frame
rendered offscreen (needs OpenGL: ``MUJOCO_GL=egl`` or ``osmesa``).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from surgsim_envs.errors import ConfigError


class PixelObservation(gym.ObservationWrapper):
    """Observation = ``(height, width, 3)`` uint8 image from ``camera``, or with ``keep_state`` a
    dict ``{"state": ..., "pixels": ...}``. Raises RenderingUnavailableError without OpenGL."""

    def __init__(self, env: gym.Env, width: int = 84, height: int = 84, camera: str | None = None,
                 keep_state: bool = False):
        super().__init__(env)
        for what, v in (("width", width), ("height", height)):
            if not isinstance(v, int) or isinstance(v, bool) or not 8 <= v <= 640:
                raise ConfigError(f"PixelObservation {what} must be an integer in [8, 640] px, got {v!r}")
        self.width, self.height, self.camera, self.keep_state = width, height, camera, keep_state
        pix = spaces.Box(0, 255, shape=(height, width, 3), dtype=np.uint8)
        self.observation_space = spaces.Dict({"state": env.observation_space, "pixels": pix}) if keep_state else pix

    def observation(self, observation):
        frame = self.env.unwrapped.render_rgb(self.width, self.height, self.camera)
        if self.keep_state:
            return {"state": observation, "pixels": frame}
        return frame
