"""LayeredPalpation-v0's reward terms, declared once in summation order: a cost per press and, on the
press that commits, ``1 - distance / size_scale`` (clipped at -1; distance in x, y from the
nodule's centre, m). The commit term applies only on that step and is absent from
``info["reward_terms"]`` otherwise (its function returns None)."""

from __future__ import annotations

from surgsim_envs.envs.terms.reward import RewardTerm


def commit_reward(distance: float, size_scale: float) -> float:
    """1 - distance / size_scale, at least -1 (both in m)."""
    return max(1.0 - distance / size_scale, -1.0)


def _press_cost(env, weight: float) -> float:
    return -weight


def _commit(env, weight: float) -> float | None:
    return commit_reward(env.distance, env.config.size_scale) if env.committed else None


REWARD_TERMS = (
    RewardTerm("press_cost", _press_cost, "press_cost", "-w per press"),
    RewardTerm("commit", _commit, None, "on the committing press: 1 - distance / size_scale (>= -1)"),
)
