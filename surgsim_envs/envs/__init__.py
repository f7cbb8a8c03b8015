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


def register_envs() -> None:
    """Register the SurgSim tasks with Gymnasium (idempotent), each with its
    ``max_episode_steps`` (:data:`MAX_EPISODE_STEPS`; Gymnasium adds its TimeLimit wrapper, and
    the env truncates at the same step itself, paying its end-of-episode terms).

    Gymnasium's passive env checker is off: after a first ``reset`` that raises (e.g. a bad
    option) it keeps no reset data and every later ``step`` failed with a TypeError. The envs
    check their own actions, options and outputs; ``gymnasium.utils.env_checker.check_env``
    passes on every task (tests/test_envs.py)."""
    import gymnasium as gym

    for env_id, entry in {**TASKS, **QUASI_STATIC_TASKS}.items():
        if env_id in gym.registry:
            continue
        gym.register(id=env_id, entry_point=entry, disable_env_checker=True,
                     max_episode_steps=MAX_EPISODE_STEPS[env_id])


__all__ = ["TASKS", "QUASI_STATIC_TASKS", "MAX_EPISODE_STEPS", "register_envs"]
