"""Every registered SurgSim task keeps its observations inside its ``observation_space`` for any
legal action: random actions and the extremes (all -1, all +1, alternating corners), a few steps
each after a reset. The task list is read from Gymnasium's registry, not written here."""

import zlib

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs  # noqa: F401 - registers the tasks
from surgsim_envs.envs import register_envs

register_envs()
REGISTERED = sorted(t for t in gym.registry if t.startswith("SurgSim/"))
PATTERNS = ("random", "all_low", "all_high", "corners")
STEPS = 3


def _cases():
    for task in REGISTERED:
        for pattern in PATTERNS:
            yield pytest.param(task, pattern, id=f"{task.split('/')[-1]}-{pattern}")


def _actions(space: gym.spaces.Box, pattern: str, rng: np.random.Generator):
    lo, hi = space.low.astype(np.float64), space.high.astype(np.float64)
    for k in range(STEPS):
        if pattern == "random":
            a = rng.uniform(lo, hi)
        elif pattern == "all_low":
            a = lo.copy()
        elif pattern == "all_high":
            a = hi.copy()
        else:   # alternating corners: entries alternate low/high, the pattern flips every step
            flip = (np.arange(lo.size) + k) % 2 == 0
            a = np.where(flip, lo, hi)
        yield a.astype(space.dtype)


def test_the_registry_lists_every_task_module():
    """The registry is the task list this file runs over: all five tasks are in it."""
    from surgsim_envs.envs import QUASI_STATIC_TASKS, TASKS

    assert set(REGISTERED) >= set(TASKS) | set(QUASI_STATIC_TASKS)
    assert len(REGISTERED) >= 5


@pytest.fixture(scope="module")
def envs():
    made = {}
    yield made
    for e in made.values():
        e.close()


@pytest.mark.parametrize("task, pattern", list(_cases()))
def test_observations_stay_in_the_space(envs, task, pattern):
    if task not in envs:
        envs[task] = gym.make(task)
    env = envs[task]
    space = env.observation_space
    rng = np.random.default_rng(zlib.crc32(f"{task}/{pattern}".encode()))
    obs, _ = env.reset(seed=int(rng.integers(2**31)))
    assert space.contains(obs), f"{task} reset: {_outside(space, obs)}"
    for k, a in enumerate(_actions(env.action_space, pattern, rng)):
        obs, reward, term, trunc, info = env.step(a)
        assert space.contains(obs), f"{task} {pattern} step {k}: {_outside(space, obs)}"
        assert np.isfinite(reward)
        if term or trunc:
            obs, _ = env.reset(seed=int(rng.integers(2**31)))
            assert space.contains(obs)


def _outside(space, obs) -> str:
    obs = np.asarray(obs)
    if obs.shape != space.shape or obs.dtype != space.dtype:
        return f"shape/dtype {obs.shape} {obs.dtype} vs {space.shape} {space.dtype}"
    bad = np.flatnonzero(~((obs >= space.low) & (obs <= space.high)) | ~np.isfinite(obs) & np.isfinite(space.low))
    return "; ".join(f"[{i}]={obs[i]!r} not in [{space.low[i]!r}, {space.high[i]!r}]" for i in bad[:5])
