"""ExamplePress-v0's scripted expert: a proportional controller on the force error."""

from __future__ import annotations

import numpy as np


def press_to_force_expert(env, gain: float = 2.0):
    """``policy(obs) -> action``: deepen the press in proportion to the relative force shortfall."""
    state = {"press": -1.0}

    def policy(obs):
        force, target = float(obs[1]), float(obs[2])
        state["press"] = float(np.clip(state["press"] + gain * (target - force) / target * 0.1, -1.0, 1.0))
        return np.array([state["press"]], dtype=np.float32)

    return policy
