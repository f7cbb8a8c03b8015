"""Export a stable-baselines3 PPO or SAC MLP policy to the ``.npz`` format of
:mod:`surgsim_envs.policies.npz_policy` (so that running a policy needs no torch). Needs torch + stable-baselines3 (the
``[train]`` extra) to *export*; the exported file runs with numpy only.

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

from surgsim_envs.errors import ConfigError
from surgsim_envs.policies.npz_policy import NpzPolicy

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
