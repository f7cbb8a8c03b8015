"""Gymnasium tasks: ``SurgSim/Palpation-v0``, ``SurgSim/Grasp-v0``, ``SurgSim/Slippage-v0``.

>>> import gymnasium as gym, surgsim_envs
>>> env = gym.make("SurgSim/Palpation-v0")          # doctest: +SKIP
>>> obs, info = env.reset(seed=0)                   # doctest: +SKIP

Config classes and scripted experts: :mod:`surgsim_envs.envs.palpation`,
:mod:`surgsim_envs.envs.grasp`, :mod:`surgsim_envs.envs.slippage`. See docs/tasks.md.
"""

from __future__ import annotations

#: task id -> "module:Class"
TASKS = {
    "SurgSim/Palpation-v0": "surgsim_envs.envs.palpation:PalpationEnv",
    "SurgSim/Grasp-v0": "surgsim_envs.envs.grasp:GraspEnv",
    "SurgSim/Slippage-v0": "surgsim_envs.envs.slippage:SlippageEnv",
    "SurgSim/PalpationPress-v0": "surgsim_envs.envs.palpation_press:PalpationPressEnv",
}
#: quasi-static tasks (one equilibrium solve per step: seconds, not microseconds; kept out of the
#: generic physics-rate env tests)
QUASI_STATIC_TASKS = {
    "SurgSim/LayeredPalpation-v0": "surgsim_envs.envs.layered_palpation:LayeredPalpationEnv",
}

#: task id -> control steps per episode of the default config (episode_seconds x control_hz); a
#: test keeps these equal to the configs. A changed config needs gym.make(..., max_episode_steps=N).
MAX_EPISODE_STEPS = {"SurgSim/Palpation-v0": 600, "SurgSim/Grasp-v0": 150, "SurgSim/Slippage-v0": 150,
                     "SurgSim/PalpationPress-v0": 25,    # one step = one press
                     "SurgSim/LayeredPalpation-v0": 30}  # one step = one quasi-static press


#: task id -> "module:Class" of its batched Warp vector env (the [batch] extra, docs/batch.md)
BATCHED = {"SurgSim/Palpation-v0": "surgsim_envs.batch.env:BatchedPalpationEnv"}


def make_vector(env_id: str, num_envs: int = 1, **kwargs):
    """Every task's ``vector_entry_point``: ``gym.make_vec(task, num_envs=n)`` (no
    ``vectorization_mode``) returns :class:`~surgsim_envs.envs.vector.SurgSimVectorEnv`, the
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
    from surgsim_envs.envs.vector import SurgSimVectorEnv

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
        if env_id in TASKS or env_id in QUASI_STATIC_TASKS:
            return functools.partial(make_vector, env_id)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def register_envs() -> None:
    """Register the SurgSim tasks with Gymnasium (idempotent), each with its
    ``max_episode_steps`` (:data:`MAX_EPISODE_STEPS`; Gymnasium adds its TimeLimit wrapper, and
    the env truncates at the same step itself, paying its end-of-episode terms) and
    :func:`make_vector` as its ``vector_entry_point`` (``gym.make_vec(task, n)`` is the
    shared-memory vector env; ``vectorization_mode="sync"``/``"async"`` give Gymnasium's).

    Gymnasium's passive env checker is off: after a first ``reset`` that raises (e.g. a bad
    option) it keeps no reset data and every later ``step`` failed with a TypeError. The envs
    check their own actions, options and outputs; ``gymnasium.utils.env_checker.check_env``
    passes on every task (tests/test_envs.py)."""
    import gymnasium as gym

    for env_id, entry in {**TASKS, **QUASI_STATIC_TASKS}.items():
        if env_id in gym.registry:
            continue
        gym.register(id=env_id, entry_point=entry, disable_env_checker=True,
                     max_episode_steps=MAX_EPISODE_STEPS[env_id],
                     vector_entry_point=f"{__name__}:{_VECTOR_ENTRY}{env_id}")


__all__ = ["TASKS", "QUASI_STATIC_TASKS", "MAX_EPISODE_STEPS", "BATCHED", "make_vector", "register_envs"]
