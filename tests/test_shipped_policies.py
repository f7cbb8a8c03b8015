"""Shipped .npz policies (issue 15): load without torch and beat random on held-out seeds,
reaching their documented success (docs/training.md)."""

from __future__ import annotations

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs  # noqa: F401
from surgsim_envs.errors import ConfigError
from surgsim_envs.policies import SHIPPED, load_shipped, shipped_path, shipped_tasks
from surgsim_envs.scenarios.policies import load_policy

#: task -> (held-out reset seeds, least successes of the shipped policy on them, env keywords).
#: The seeds are the first 8 of the documented evaluation (docs/training.md; never used in
#: training: training resets are seeded 0/1, then the envs' own generators). Documented: 5/20 = 25 %
#: on seeds 10001-10020 against random 1/20; measured here 2/8 against random 1/8. This is BELOW
#: the issue's 70 % target (docs/training.md says why); the test pins what ships.
HELD_OUT = {
    "SurgSim/PalpationPress-v0": (range(10_001, 10_009), 2, {}),
}


def rollout(env, policy, seed):
    obs, _ = env.reset(seed=seed)
    total = 0.0
    while True:
        obs, r, term, trunc, info = env.step(policy(obs))
        total += r
        if term or trunc:
            return bool(info["success"]), total


def test_every_shipped_policy_is_present_and_evaluated_here():
    assert shipped_tasks() == list(SHIPPED)
    assert set(HELD_OUT) == set(SHIPPED)


def test_shipped_policies_load_without_torch():
    code = ("import sys; from surgsim_envs.policies import load_shipped, SHIPPED\n"
            "for t in SHIPPED: load_shipped(t)\n"
            "assert 'torch' not in sys.modules and 'stable_baselines3' not in sys.modules, 'torch imported'\n")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


def test_unknown_task_names_the_shipped_ones():
    with pytest.raises(ConfigError, match="PalpationPress"):
        shipped_path("SurgSim/NoSuchTask-v0")
    assert callable(load_policy("shipped:SurgSim/PalpationPress-v0"))
    with pytest.raises(ConfigError, match="no shipped policy"):
        load_policy("shipped:SurgSim/NoSuchTask-v0")


@pytest.mark.parametrize("task", sorted(HELD_OUT))
def test_shipped_policy_beats_random_on_held_out_seeds(task):
    seeds, least, kwargs = HELD_OUT[task]
    env = gym.make(task, **kwargs)
    policy = load_shipped(task)
    assert policy.obs_size == env.observation_space.shape[0] and policy.action_size == env.action_space.shape[0]
    trained = [rollout(env, policy, s) for s in seeds]
    env.action_space.seed(0)
    rand = [rollout(env, lambda o: env.action_space.sample(), s) for s in seeds]
    env.close()
    assert sum(ok for ok, _ in trained) >= least
    assert sum(ok for ok, _ in trained) > sum(ok for ok, _ in rand)
    assert all(np.isfinite(r) for _, r in trained)
