"""Optional wrappers for the SurgSim tasks.

:class:`PixelObservation` replaces (or augments) the state observation with an RGB frame
rendered offscreen (needs OpenGL: ``MUJOCO_GL=egl`` or ``osmesa``). :class:`InfoKeys` keeps only
the named info entries (cheaper async vector envs).
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


class InfoKeys(gym.Wrapper):
    """Keep only ``keys`` of every ``info`` (reset and step), for vector envs that do not need the
    rest: an async vector env pickles each step's info in the worker and merges the infos of all
    workers key by key in the main process (Gymnasium's ``VectorEnv._add_info``), serially, and
    with the tasks' ~17 info entries that costs more than the pipe round-trip itself (measured:
    CHANGELOG.md, "Env step: three-pass spring kernel, env fast paths, Grasp sub-cycling"). Keys missing from an info are skipped.

    ``gym.make_vec("SurgSim/Palpation-v0", num_envs=2, vectorization_mode="async",
    wrappers=[functools.partial(InfoKeys, keys=("is_success",))])``
    """

    def __init__(self, env: gym.Env, keys=("success", "is_success")):
        super().__init__(env)
        if isinstance(keys, str) or not all(isinstance(k, str) for k in keys):
            raise ConfigError(f"InfoKeys keys must be a sequence of info key names (str), got {keys!r}")
        self.keys = tuple(keys)

    def _slim(self, info: dict) -> dict:
        return {k: info[k] for k in self.keys if k in info}

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        return obs, self._slim(info)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, self._slim(info)
