"""Grasp-v0's scripted expert: close the jaws until every jaw holds, then carry the organ straight to
the target, keeping each jaw under the damage force."""

from __future__ import annotations

import numpy as np


def grasp_expert(env, close_rate: float = 0.1, hold: float = 0.15, limit: float = 0.8, trim: float = 0.05,
                 close_steps: int = 30):
    """Scripted policy: close (the closure action rising by ``close_rate`` a step) until every jaw presses
    ``hold`` N or ``close_steps`` steps have passed, then move straight to the target while trimming the
    closure by ``trim`` a step: open while a jaw presses more than ``limit`` x the task's damage force,
    close while a jaw presses less than ``hold`` N.

    Why force feedback rather than a fixed closure: the same closure squeezes a stiff model far harder
    than a soft one. A full closure stays under 1 N per jaw on the explicit network, where this policy
    acts as a full closure does, but drives the quasi-static FEM past 8 N (docs/task_accuracy.md)."""
    cfg = env.unwrapped.config
    state = {"n": 0, "c": -1.0, "held": False}

    def policy(obs):
        state["n"] += 1
        normal = obs[7:10]                      # per-jaw normal force, N
        if not state["held"]:
            if normal.min() >= hold or state["n"] > close_steps:
                state["held"] = True
            else:
                state["c"] = min(1.0, state["c"] + close_rate)
                return np.array([0.0, 0.0, 0.0, state["c"]], dtype=np.float32)
        if normal.max() > limit * cfg.damage_force:
            state["c"] -= trim
        elif normal.min() < hold:
            state["c"] += trim
        state["c"] = float(np.clip(state["c"], -1.0, 1.0))
        rel = obs[3:6]                          # target minus wrist, m
        return np.array([*np.clip(rel / cfg.max_step * 0.6, -0.6, 0.6), state["c"]], dtype=np.float32)

    return policy
