"""ExamplePress-v0's term functions (each testable alone) and its term declarations."""

from __future__ import annotations

from surgsim_envs.envs.terms.reward import RewardTerm


def force_error_penalty(force_z: float, target: float, weight: float) -> float:
    """-weight * |force_z - target| / target: the relative error of the pressing force (N)."""
    return -weight * abs(force_z - target) / target


def _force_error(env, weight: float) -> float:
    return force_error_penalty(env.readings()[1][2], env.config.target_force, weight)


#: the reward, in summation order (no termination term: the episode ends at the time limit)
REWARD_TERMS = (
    RewardTerm("force_error", _force_error, "force_weight", "-w |F_z - target_force| / target_force per step"),
)
