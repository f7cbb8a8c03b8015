"""PalpationPress-v0's scripted expert: press every map cell in raster order, then report."""

from __future__ import annotations

from typing import Any

import numpy as np


def press_expert(env) -> Any:
    """Scripted policy: press the centre of every map cell in raster order (the observation's
    ``next_unsampled_cell_xy``), report when all are sampled. Returns ``policy(obs) -> action``."""
    u = env.unwrapped
    hw = float(u.config.map_half_width)
    names = u.observation_names
    i_next, i_free = names.index("next_unsampled_cell_xy[0] [m]"), names.index("unsampled_fraction [1]")

    def policy(obs):
        obs = np.asarray(obs, dtype=float)
        nxt, unsampled = obs[i_next:i_next + 2], obs[i_free]
        if unsampled <= 0.0:
            return np.array([0.0, 0.0, 1.0], dtype=np.float32)
        return np.array([nxt[0] / hw, nxt[1] / hw, -1.0], dtype=np.float32)

    return policy
