"""Palpation-v0's scripted expert: a raster of presses, then report."""

from __future__ import annotations

from typing import Any

import numpy as np


def palpation_expert(env, grid: int = 5, depth_action: float = 0.6) -> Any:
    """A scripted policy: press ``depth_action`` (6 mm deep) for 12 control steps at each site of a
    ``grid`` x ``grid`` raster over the inclusion's range, then report (the env's stiffness-weighted
    estimate of the samples is the guess). Returns a callable ``policy(obs) -> action``."""
    c = env.unwrapped.config
    lim = float(min(c.inclusion_xy[1], c.xy_limit))
    xs = np.linspace(-lim, lim, grid)
    pts = [np.array([x, y]) for j, y in enumerate(np.linspace(-lim, lim, grid)) for x in (xs if j % 2 == 0 else xs[::-1])]
    state = {"i": 0, "phase": "move", "n": 0}

    def policy(obs):
        if state["i"] == len(pts):
            return np.array([0, 0, -1, 1], dtype=np.float32)
        d = pts[state["i"]] - obs[:2]
        if state["phase"] == "move":
            if np.hypot(*d) < 0.0015:
                state["phase"], state["n"] = "press", 0
            return np.array([*np.clip(d / c.max_xy_step, -1, 1), -1, -1], dtype=np.float32)
        state["n"] += 1
        if state["n"] >= 12:
            state["i"] += 1
            state["phase"] = "move"
            return np.array([0, 0, -1, -1], dtype=np.float32)
        return np.array([*np.clip(d / c.max_xy_step, -1, 1), depth_action, -1], dtype=np.float32)

    return policy
