"""Gymnasium tasks: one folder per task (``palpation/``, ``grasp/``, ``slippage/``,
``palpation_press/``, ``layered_palpation/``) and one :class:`~surgsim_envs.envs.registry.TaskSpec`
each in :mod:`surgsim_envs.envs.registry`.

>>> import gymnasium as gym, surgsim_envs
>>> env = gym.make("SurgSim/Palpation-v0")          # doctest: +SKIP
>>> obs, info = env.reset(seed=0)                   # doctest: +SKIP

Shared machinery: :mod:`.base` (the env base class), :mod:`.terms` (observation, reward,
termination and action terms), :mod:`.checks` (config checks), :mod:`.tissue_setup`. See
docs/tasks.md and docs/adding_a_task.md.
"""

from __future__ import annotations

from surgsim_envs.envs.registry import TASKS as _SPECS

#: task id -> "module:Class" of the physics-rate tasks (derived from the registry,
#: :mod:`surgsim_envs.envs.registry`, for the callers that read it; a task added later with
#: ``registry.register`` is in the registry only)
TASKS = {tid: spec.entry_point for tid, spec in _SPECS.items() if not spec.quasi_static}
#: task id -> "module:Class" of the quasi-static tasks (one equilibrium solve per step: seconds, not
#: microseconds; kept out of the generic physics-rate env tests)
QUASI_STATIC_TASKS = {tid: spec.entry_point for tid, spec in _SPECS.items() if spec.quasi_static}
#: task id -> control steps per episode of the default config (``TaskSpec.max_episode_steps``); a
#: test keeps these equal to the configs. A changed config needs gym.make(..., max_episode_steps=N).
MAX_EPISODE_STEPS = {tid: spec.max_episode_steps for tid, spec in _SPECS.items()}


#: task id -> "module:Class" of its batched Warp vector env (``TaskSpec.batched``; the [batch] extra,
#: docs/batch.md)
BATCHED = {tid: spec.batched for tid, spec in _SPECS.items() if spec.batched}


def make_vector(env_id: str, num_envs: int = 1, **kwargs):
    """Every task's ``vector_entry_point``: ``gym.make_vec(task, num_envs=n)`` (no
    ``vectorization_mode``) returns :class:`~surgsim_envs.vector.SurgSimVectorEnv`, the
    shared-memory multi-process vector env; its options (``workers=``, ``info_keys=``,
    ``autoreset_mode=``, ...) go in make_vec's keyword arguments, next to the env's own.

    With ``device=`` ("cpu", "cuda") it returns the task's batched Warp env instead (:data:`BATCHED`).
    That package sits above this one (it reuses the tasks' configs and terms), so it is loaded by
    its entry-point string, as Gymnasium loads entry points, not imported here."""
    if "device" in kwargs:
        if env_id not in BATCHED:
            from surgsim_envs.errors import ConfigError

            raise ConfigError(f"device= (the batched Warp backend) is available for {sorted(BATCHED)}, not {env_id!r}; "
                              "leave device out for the multi-process vector env")
        from gymnasium.envs.registration import load_env_creator

        return load_env_creator(BATCHED[env_id])(num_envs=num_envs, **kwargs)
    from surgsim_envs.vector import SurgSimVectorEnv

    return SurgSimVectorEnv(env_id, num_envs, **kwargs)


#: a task's vector_entry_point is the string "surgsim_envs.envs:make_vector|<task id>", which
#: Gymnasium resolves with getattr(surgsim_envs.envs, "make_vector|<task id>") (module __getattr__
#: below): a string keeps the spec JSON-serialisable (EnvSpec.to_json, Minari), a callable would not
_VECTOR_ENTRY = "make_vector|"


def __getattr__(name: str):
    """``"make_vector|<task id>"`` -> :func:`make_vector` bound to that task (see _VECTOR_ENTRY)."""
    if name.startswith(_VECTOR_ENTRY):
        import functools

        env_id = name[len(_VECTOR_ENTRY):]
        if env_id in _SPECS:
            return functools.partial(make_vector, env_id)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def register_envs() -> None:
    """Register every task of the registry with Gymnasium (idempotent; see
    :func:`surgsim_envs.envs.registry.register_with_gymnasium`)."""
    from surgsim_envs.envs.registry import register_with_gymnasium

    for spec in _SPECS.values():
        register_with_gymnasium(spec)


__all__ = ["TASKS", "QUASI_STATIC_TASKS", "MAX_EPISODE_STEPS", "BATCHED", "make_vector", "register_envs"]
