"""stable-baselines3 glue (needs the [train] extra): a ``VecEnv`` on the shared-memory vector env, and
the export of a trained SB3 policy to the numpy-only ``.npz`` format.

**Vector env.** stable-baselines3 over :class:`~surgsim_envs.vector.SurgSimVectorEnv`: an SB3 ``VecEnv``
whose envs run in the shared-memory workers instead of SubprocVecEnv's pipes.

>>> from surgsim_envs.integrations.sb3 import make_sb3_vec_env       # doctest: +SKIP
>>> venv = make_sb3_vec_env("SurgSim/Grasp-v0", n_envs=2, seed=0)  # VecMonitor(SB3VectorEnv)
>>> model = stable_baselines3.PPO("MlpPolicy", venv)                # doctest: +SKIP

SB3 semantics: the envs autoreset in the step that ends an episode (``autoreset_mode=SAME_STEP``
underneath), ``infos[i]["terminal_observation"]`` and ``infos[i]["TimeLimit.truncated"]``,
the reset info in ``reset_infos[i]``, seeds and options from ``seed()``/``set_options()`` used at
the next ``reset()``. Infos carry only ``info_keys`` (default ``("is_success",)``, what SB3 reads
for its success rate; ``"all"`` for every entry) as Python scalars.

**Policy export.** Export a stable-baselines3 PPO or SAC MLP policy to the ``.npz`` format of
:mod:`surgsim_envs.policies.npz_policy` (so that running a policy needs no torch). Exporting needs torch
+ stable-baselines3; the exported file runs with numpy only.

Mapping (deterministic actions, as ``model.predict(obs, deterministic=True)``):

* PPO ``ActorCriticPolicy``: ``mlp_extractor.policy_net`` (Linear + activation)* then
  ``action_net`` (Linear); the action is the Gaussian mean clipped to the action space bounds
  (``action_low``/``action_high``).
* SAC ``Actor``: ``latent_pi`` (Linear + activation)* then ``mu`` (Linear) and ``tanh``; the
  action is ``low + (tanh + 1) (high - low) / 2`` (``action_scale``/``action_bias``).
* ``VecNormalize`` observation statistics: ``obs_mean`` = running mean, ``obs_std`` =
  ``sqrt(var + epsilon)``, ``obs_clip`` = ``clip_obs``.

:func:`check_export` compares the numpy actions with SB3's on sample observations.
"""

from __future__ import annotations

import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecMonitor

from surgsim_envs.errors import ConfigError
from surgsim_envs.policies.npz_policy import NpzPolicy
from surgsim_envs.vector import SurgSimVectorEnv


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


# -- policy export ------------------------------------------------------------------------------
#: torch activation class name -> npz activation name
_ACTIVATIONS = {"Tanh": "tanh", "ReLU": "relu", "ELU": "elu", "Identity": "identity"}


def _linear_stack(modules) -> tuple[list, list, str]:
    """(weights (in, out), biases, activation) of a Sequential of Linear/activation layers."""
    import torch.nn as nn

    weights, biases, acts = [], [], set()
    for m in modules:
        if isinstance(m, nn.Linear):
            weights.append(m.weight.detach().cpu().numpy().T.astype(np.float64))
            biases.append(m.bias.detach().cpu().numpy().astype(np.float64))
        elif type(m).__name__ in _ACTIVATIONS:
            acts.add(_ACTIVATIONS[type(m).__name__])
        else:
            raise ConfigError(f"cannot export layer {type(m).__name__}: only Linear and {sorted(_ACTIVATIONS)} "
                              "activations map onto the .npz MLP format")
    if len(acts) > 1:
        raise ConfigError(f"cannot export mixed hidden activations {sorted(acts)}; the .npz format has one")
    return weights, biases, (acts.pop() if acts else "tanh")


def sb3_to_npz(model, vecnormalize=None, source: str = "<sb3 export>", mode: str = "deterministic") -> NpzPolicy:
    """:class:`NpzPolicy` with the actions of SB3 ``model`` (PPO/A2C or SAC with an MLP policy on a
    Box observation and Box action space); ``vecnormalize`` the training ``VecNormalize`` (or
    None). The Gaussian head is exported too (PPO's ``log_std`` parameter, SAC's ``log_std``
    layer and its clip); ``mode`` records how the policy acts by default."""
    policy = model.policy
    space = model.action_space
    low, high = np.asarray(space.low, dtype=np.float64), np.asarray(space.high, dtype=np.float64)
    kw = {}
    if hasattr(policy, "mlp_extractor") and hasattr(policy, "action_net"):          # PPO / A2C
        if type(policy.action_dist).__name__ != "DiagGaussianDistribution":
            raise ConfigError(f"cannot export {type(policy.action_dist).__name__}: only Gaussian (Box) actions")
        w, b, act = _linear_stack(policy.mlp_extractor.policy_net)
        hw, hb, _ = _linear_stack([policy.action_net])
        kw = dict(action_low=low, action_high=high, output_activation="identity",
                  log_std=policy.log_std.detach().cpu().numpy().astype(np.float64))
    elif hasattr(policy, "actor") and hasattr(policy.actor, "mu"):                     # SAC / TD3-like
        if getattr(policy.actor, "use_sde", False):
            raise ConfigError("cannot export a gSDE SAC actor; train with use_sde=False")
        w, b, act = _linear_stack(policy.actor.latent_pi)
        hw, hb, _ = _linear_stack([policy.actor.mu])
        sw, sb, _ = _linear_stack([policy.actor.log_std])
        from stable_baselines3.sac.policies import LOG_STD_MAX, LOG_STD_MIN

        kw = dict(log_std_W=sw[0], log_std_b=sb[0], log_std_min=LOG_STD_MIN, log_std_max=LOG_STD_MAX,action_scale=(high - low) / 2.0, action_bias=(high + low) / 2.0, action_low=low,
                  action_high=high, output_activation="tanh")
    else:
        raise ConfigError(f"cannot export policy {type(policy).__name__}; PPO/A2C and SAC MLP policies are supported")
    if vecnormalize is not None and getattr(vecnormalize, "norm_obs", False):
        rms = vecnormalize.obs_rms
        kw.update(obs_mean=np.asarray(rms.mean, dtype=np.float64),
                  obs_std=np.sqrt(np.asarray(rms.var, dtype=np.float64) + vecnormalize.epsilon),
                  obs_clip=float(vecnormalize.clip_obs))
    return NpzPolicy(w + hw, b + hb, activation=act, source=source, mode=mode, **kw)


def check_export(model, npz: NpzPolicy, observations, vecnormalize=None, atol: float = 1e-4) -> float:
    """Largest |numpy action - SB3 deterministic action| over ``observations`` (n, obs) in raw
    (unnormalised) units; ConfigError if above ``atol``."""
    obs = np.asarray(observations, dtype=np.float32)
    sb3_in = vecnormalize.normalize_obs(obs) if vecnormalize is not None else obs
    ref, _ = model.predict(sb3_in, deterministic=True)
    mode = npz.mode
    npz.with_mode("deterministic")
    try:
        ours = np.stack([npz(o) for o in obs])
    finally:
        npz.with_mode(mode)
    err = float(np.max(np.abs(ours - ref)))
    if not err <= atol:
        raise ConfigError(f"exported policy differs from SB3 by {err:.3g} > {atol:g}; the export is wrong")
    return err
