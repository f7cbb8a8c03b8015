"""Tiny scripted policies that scenario files can name as ``"surgsim_envs.scenarios.policies:NAME"``
(no stable-baselines3 needed).

* :func:`palpation_scan` (task ``SurgSim/Palpation-v0``, a factory taking ``env``): presses on a
  raster, then reports at the stiffest site.
* :func:`hold_still` (phase scenarios): keeps the tool where it is.
"""

from __future__ import annotations

import numpy as np


def palpation_scan(env, grid: int = 4, settle_steps: int = 12, press: float = 0.6):
    """Factory: a raster palpation policy for SurgSim/Palpation-v0 (action ``[vx, vy, press, report]``).

    Moves over a ``grid`` x ``grid`` raster spanning the inclusion's possible positions, presses
    ``settle_steps`` control steps at each site, records force / depth (N/m) from the observation
    (``obs[5]`` force z, ``obs[6]`` depth), then goes to the stiffness-weighted centroid of the
    stiffest sites and reports."""
    c = env.unwrapped.config
    lim = float(min(max(abs(v) for v in c.inclusion_xy), c.xy_limit))
    xs = np.linspace(-lim, lim, grid)
    sites = [np.array([x, y]) for j, y in enumerate(xs) for x in (xs if j % 2 == 0 else xs[::-1])]
    step = float(c.max_xy_step)
    state = {"i": 0, "n": 0, "k": [], "goal": None}

    def move(pos, goal, pressing):
        d = np.clip((goal - pos[:2]) / step, -1.0, 1.0)
        return np.array([d[0], d[1], press if pressing else -1.0, -1.0], dtype=np.float32)

    def policy(obs):
        pos = np.asarray(obs[:3], dtype=float)
        if state["goal"] is not None:
            if np.hypot(*(state["goal"] - pos[:2])) < 0.001:
                return np.array([0.0, 0.0, -1.0, 1.0], dtype=np.float32)
            return move(pos, state["goal"], False)
        site = sites[state["i"]]
        if np.hypot(*(site - pos[:2])) > 0.0015 and state["n"] == 0:
            return move(pos, site, False)
        state["n"] += 1
        if state["n"] < settle_steps:
            return move(pos, site, True)
        state["k"].append(float(obs[5]) / max(float(obs[6]), 1e-4))
        state["n"] = 0
        state["i"] += 1
        if state["i"] == len(sites):
            k = np.asarray(state["k"])
            w = np.clip(k - np.median(k), 0.0, None) ** 2
            pts = np.asarray(sites)
            state["goal"] = (w[:, None] * pts).sum(0) / w.sum() if w.sum() > 0 else pts[int(np.argmax(k))]
        return move(pos, site, False)

    return policy


def hold_still(obs: dict) -> dict:
    """Phase-scenario policy: keep the current tool offset and jaw opening."""
    return {"offset": obs["offset"], "opening": obs["opening"]}
