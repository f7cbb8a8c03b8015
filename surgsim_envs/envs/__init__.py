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
}
#: quasi-static tasks (one equilibrium solve per step: seconds, not microseconds; kept out of the
#: generic physics-rate env tests)
QUASI_STATIC_TASKS = {
    "SurgSim/LayeredPalpation-v0": "surgsim_envs.envs.layered_palpation:LayeredPalpationEnv",
}


def register_envs() -> None:
    """Register the SurgSim tasks with Gymnasium (idempotent). Time limits are applied by the
    envs themselves (``config.episode_seconds``), so no TimeLimit wrapper is added."""
    import gymnasium as gym

    for env_id, entry in {**TASKS, **QUASI_STATIC_TASKS}.items():
        if env_id in gym.registry:
            continue
        gym.register(id=env_id, entry_point=entry, disable_env_checker=False)


__all__ = ["TASKS", "QUASI_STATIC_TASKS", "register_envs"]
