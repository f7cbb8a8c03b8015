"""Grasp-v0's scripted expert: close the jaws, wait, then move straight to the target."""

from __future__ import annotations

import numpy as np


def grasp_expert(env, close_action: float = 1.0, close_steps: int = 30):
    """Scripted policy: close the jaws, wait, then move straight to the target."""
    state = {"n": 0}

    def policy(obs):
        state["n"] += 1
        if state["n"] <= close_steps:
            return np.array([0, 0, 0, close_action], dtype=np.float32)
        rel = obs[3:6]
        step = env.unwrapped.config.max_step
        return np.array([*np.clip(rel / step * 0.6, -0.6, 0.6), close_action], dtype=np.float32)

    return policy
