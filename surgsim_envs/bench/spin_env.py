"""A synthetic env for timing what a vector env itself costs (pipes, scheduling, info merging)."""

from __future__ import annotations

import time

import numpy as np


class SpinEnv:
    """A trivial Gymnasium env whose step busy-waits ``step_us`` microseconds (0: returns at once),
    with a 20-float observation: the async baseline (pipe round-trip and process scheduling only).
    ``info``: the info dict each step returns (a fresh deep copy per step; default empty), e.g. a
    task's own, to see what sending and merging it costs."""

    def __new__(cls, step_us: float = 0.0, info: dict | None = None):
        import copy
        import gymnasium as gym
        from gymnasium import spaces

        class _Spin(gym.Env):
            observation_space = spaces.Box(-1.0, 1.0, (20,), np.float32)
            action_space = spaces.Box(-1.0, 1.0, (4,), np.float32)

            def reset(self, *, seed=None, options=None):
                super().reset(seed=seed)
                return np.zeros(20, np.float32), {}

            def step(self, action):
                end = time.perf_counter() + step_us * 1e-6
                while time.perf_counter() < end:
                    pass
                return np.zeros(20, np.float32), 0.0, False, False, copy.deepcopy(info) if info else {}

        return _Spin()
