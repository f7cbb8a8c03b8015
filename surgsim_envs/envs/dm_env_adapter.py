"""A thin dm_env adapter for the SurgSim tasks (``pip install dm-env``; imported lazily).

>>> from surgsim_envs.envs.dm_env_adapter import make_dm_env
>>> env = make_dm_env("SurgSim/Palpation-v0", seed=0)   # doctest: +SKIP
>>> ts = env.reset(); ts = env.step(env.action_spec().generate_value())   # doctest: +SKIP

Truncation (time limit) ends the episode with ``discount=1`` (dm_env's truncation convention),
termination with ``discount=0``.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.errors import ConfigError


def make_dm_env(env_id: str, seed: int | None = None, **kwargs):
    """A dm_env.Environment wrapping ``gym.make(env_id, **kwargs)``."""
    try:
        import dm_env  # noqa: F401
    except ImportError as exc:
        raise ConfigError("the dm_env adapter needs dm-env: pip install dm-env (or the [test] extra)") from exc
    import gymnasium as gym

    import surgsim_envs  # noqa: F401  (registers the tasks)

    return DmEnvAdapter(gym.make(env_id, **kwargs), seed=seed)


def _adapter_class():
    import dm_env
    from dm_env import specs

    class _DmEnvAdapter(dm_env.Environment):
        def __init__(self, env, seed=None):
            self.env = env
            self._seed = seed
            self._reset_next = True
            space = env.observation_space
            self._obs_spec = specs.Array(space.shape, space.dtype, name="observation")
            a = env.action_space
            self._act_spec = specs.BoundedArray(a.shape, a.dtype, a.low, a.high, name="action")

        def reset(self):
            obs, _ = self.env.reset(seed=self._seed)
            self._seed = None
            self._reset_next = False
            return dm_env.restart(np.asarray(obs))

        def step(self, action):
            if self._reset_next:
                return self.reset()
            obs, reward, terminated, truncated, self.last_info = self.env.step(action)
            obs = np.asarray(obs)
            if terminated:
                self._reset_next = True
                return dm_env.termination(reward, obs)
            if truncated:
                self._reset_next = True
                return dm_env.truncation(reward, obs)
            return dm_env.transition(reward, obs)

        def observation_spec(self):
            return self._obs_spec

        def action_spec(self):
            return self._act_spec

        def close(self):
            self.env.close()

    return _DmEnvAdapter


def DmEnvAdapter(env, seed: int | None = None):
    """Wrap a Gymnasium env as a dm_env.Environment (the class is built on first use)."""
    return _adapter_class()(env, seed)
