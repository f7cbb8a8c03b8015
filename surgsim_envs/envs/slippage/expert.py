"""Slippage-v0's scripted expert: close in proportion to the pull, tighten while nodes slip."""

from __future__ import annotations

import numpy as np


def slippage_expert(env, base: float = 0.7, gain: float = 2.0, slip_gain: float = 0.1):
    """Scripted policy: close in proportion to the pull force and tighten further while nodes slip."""
    state = {"extra": 0.0}

    def policy(obs):
        slipping, pull = obs[7], obs[9]
        if slipping > 0:
            state["extra"] = min(1.0, state["extra"] + slip_gain)
        return np.array([np.clip(base + gain * pull + state["extra"], -1.0, 1.0)], dtype=np.float32)

    return policy
