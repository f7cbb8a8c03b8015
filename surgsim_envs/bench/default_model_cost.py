"""A task's default env step against the same task on the plain ``mass_spring`` network.

"Plain" is ``MassSpringModel`` as built by default: springs and Maxwell branches, no volume term.
A task may build its default model with options of its own (the palpation tasks build
``mass_spring`` with its ``point_load_options``, the capped volume term), or default to another
model. The two envs are stepped alternately in one process, timed run against timed run with the
same seeded random actions (Palpation's "report" component held off), so that a changing host load
hits both alike; the figures are medians over the runs, and the ratio is that of the medians.
"""

from __future__ import annotations

import contextlib
import statistics
import time

import numpy as np

#: the model the default is compared with
PLAIN_MODEL = "mass_spring"
#: the lattice the plain network is built on where the task's default lattice is another: 10 mm for the
#: palpation slab, where it steps explicitly (on a finer lattice the task's stiffest lump makes it implicit)
PLAIN_LATTICE = {"SurgSim/Palpation-v0": {"spacing": 0.01}, "SurgSim/PalpationPress-v0": {"spacing": 0.01}}


@contextlib.contextmanager
def plain_network():
    """Envs made inside build ``mass_spring`` without the options a task adds for concentrated loads."""
    from surgsim_envs.tissue.mass_spring import MassSpringModel

    saved = MassSpringModel.point_load_options
    MassSpringModel.point_load_options = {}
    try:
        yield
    finally:
        MassSpringModel.point_load_options = saved


def _timed_run(env, actions, seed: int) -> float:
    """Wall time (s) of ``len(actions)`` env steps from a reset with ``seed`` (episode ends reset)."""
    env.reset(seed=seed)
    t0 = time.perf_counter()
    for a in actions:
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    return time.perf_counter() - t0


def default_vs_plain(env_id: str, steps: int, repeats: int) -> dict:
    """``{"default_model", "default_options", "default_step_us", "plain_step_us", "default_over_plain"}``
    for task ``env_id``: median env step (us) of the task as ``gym.make(env_id)`` builds it and of the
    same task on the plain network (on :data:`PLAIN_LATTICE` where given), stepped alternately in this
    process."""
    import gymnasium as gym

    from surgsim_envs.bench.random_actions import random_actions as _actions

    default = gym.make(env_id)
    with plain_network():
        plain = gym.make(env_id, model=PLAIN_MODEL, **PLAIN_LATTICE.get(env_id, {}))
    tissue = default.unwrapped.sim.tissue()
    pal = "Palpation" in env_id
    rng = np.random.default_rng(0)
    for env in (default, plain):                 # warm-up: compiles numba kernels
        env.reset(seed=0)
        for a in _actions(env.action_space, 20, rng, pal):
            env.step(a)
    times = {"default": [], "plain": []}
    for r in range(repeats):
        actions = _actions(default.action_space, steps, np.random.default_rng(100 + r), pal)
        for name, env in (("default", default), ("plain", plain)):
            times[name].append(_timed_run(env, actions, r) / steps)
    d_us = statistics.median(times["default"]) * 1e6
    p_us = statistics.median(times["plain"]) * 1e6
    desc = tissue.describe()
    plain_desc = plain.unwrapped.sim.tissue().describe()
    out = {"default_model": tissue.name, "default_volume_stiffness": desc.get("volume_stiffness"),
           "plain_volume_stiffness": plain_desc.get("volume_stiffness"),
           "default_step_us": d_us, "plain_step_us": p_us, "default_over_plain": d_us / p_us}
    default.close()
    plain.close()
    return out
