"""stable-baselines3 over :class:`~surgsim_envs.vector.SurgSimVectorEnv`: an SB3 ``VecEnv``
whose envs run in the shared-memory workers instead of SubprocVecEnv's pipes (needs the
[train] extra).

>>> from surgsim_envs.envs.vector_sb3 import make_sb3_vec_env       # doctest: +SKIP
>>> venv = make_sb3_vec_env("SurgSim/Grasp-v0", n_envs=2, seed=0)  # VecMonitor(SB3VectorEnv)
>>> model = stable_baselines3.PPO("MlpPolicy", venv)                # doctest: +SKIP

SB3 semantics: the envs autoreset in the step that ends an episode (``autoreset_mode=SAME_STEP``
underneath), ``infos[i]["terminal_observation"]`` and ``infos[i]["TimeLimit.truncated"]``,
the reset info in ``reset_infos[i]``, seeds and options from ``seed()``/``set_options()`` used at
the next ``reset()``. Infos carry only ``info_keys`` (default ``("is_success",)``, what SB3 reads
for its success rate; ``"all"`` for every entry) as Python scalars.
"""

from __future__ import annotations

import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecMonitor

from surgsim_envs.vector import SurgSimVectorEnv
from surgsim_envs.errors import ConfigError


class SB3VectorEnv(VecEnv):
    """``n_envs`` copies of task ``env_id`` in a :class:`SurgSimVectorEnv` (``**kwargs``: its
    options, e.g. ``workers=``, and the env's own keyword arguments)."""

    def __init__(self, env_id, n_envs: int, info_keys=("is_success",), **kwargs):
        self.venv = SurgSimVectorEnv(env_id, n_envs, autoreset_mode="SameStep", info_keys=info_keys, **kwargs)
        super().__init__(n_envs, self.venv.single_observation_space, self.venv.single_action_space)
        self._actions = None

    def reset(self):
        seeds = list(self._seeds)
        options = self._options[0] if self._options else {}
        if any(o != options for o in self._options):
            raise ConfigError("SB3VectorEnv passes one options dict to every env; set_options() got different "
                              f"ones per env: {self._options}")
        obs, info = self.venv.reset(seed=seeds, options=options or None)
        self.reset_infos = _per_env(info, self.num_envs)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions) -> None:
        self.venv.step_async(np.asarray(actions).reshape(self.venv.action_space.shape))

    def step_wait(self):
        obs, rewards, terminated, truncated, info = self.venv.step_wait()
        dones = terminated | truncated
        if not dones.any():
            return obs, rewards.astype(np.float32), dones, _per_env(info, self.num_envs)
        top = _per_env({k: v for k, v in info.items() if not k.startswith(("final_", "_final_"))}, self.num_envs)
        final = _per_env(info["final_info"], self.num_envs)
        infos = []
        for i in range(self.num_envs):
            if dones[i]:
                self.reset_infos[i] = top[i]
                d = final[i]
                d["terminal_observation"] = info["final_obs"][i]
                d["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            else:
                d = top[i]
            infos.append(d)
        return obs, rewards.astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name, indices=None) -> list:
        return list(self.venv.call_envs(self._get_indices(indices), attr_name))

    def set_attr(self, attr_name, value, indices=None) -> None:
        idx = list(self._get_indices(indices))
        self.venv.set_attr(attr_name, [value] * len(idx), indices=idx)

    def env_method(self, method_name, *method_args, indices=None, **method_kwargs) -> list:
        return list(self.venv.call_envs(self._get_indices(indices), method_name, *method_args, **method_kwargs))

    def env_is_wrapped(self, wrapper_class, indices=None) -> list:
        """The envs are ``gym.make(task)``: wrapped in Gymnasium's TimeLimit and OrderEnforcing only
        (SB3 asks about its Monitor, which VecMonitor replaces)."""
        from gymnasium.wrappers import OrderEnforcing, TimeLimit

        inside = any(issubclass(w, wrapper_class) for w in (TimeLimit, OrderEnforcing))
        return [inside] * len(self._get_indices(indices))

    def get_images(self):
        return list(self.venv.call("render"))


def _per_env(info: dict, n: int) -> list:
    """Gymnasium's vector info (arrays + ``_key`` masks) -> one dict of Python scalars per env."""
    out = [{} for _ in range(n)]
    for key, value in info.items():
        if key.startswith("_"):
            continue
        mask = info.get("_" + key)
        if mask is None:
            continue
        if isinstance(value, dict):
            sub = _per_env(value, n)
            for i in np.flatnonzero(mask):
                out[i][key] = sub[i]
            continue
        items = value.tolist()
        for i in np.flatnonzero(mask).tolist():
            out[i][key] = items[i]
    return out


def make_sb3_vec_env(env_id: str, n_envs: int, seed: int | None = None, env_kwargs: dict | None = None,
                     monitor: bool = True, **vector_kwargs):
    """SB3's ``make_vec_env`` for the shared-memory vector env: :class:`SB3VectorEnv` seeded like
    ``make_vec_env`` (env i gets ``seed + i`` at the first reset) and wrapped in ``VecMonitor``
    (episode returns and lengths for SB3's logger, as ``make_vec_env``'s per-env ``Monitor``)."""
    if not isinstance(n_envs, int) or n_envs < 1:
        raise ConfigError(f"n_envs must be an integer >= 1, got {n_envs!r}")
    venv = SB3VectorEnv(env_id, n_envs, **(env_kwargs or {}), **vector_kwargs)
    if seed is not None:
        venv.seed(seed)
    return VecMonitor(venv) if monitor else venv
