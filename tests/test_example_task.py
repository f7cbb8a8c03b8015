"""The worked example of docs/adding_a_task.md: a task is one folder plus one TaskSpec. The test
registers the example from its spec alone, runs Gymnasium's env checker on it and checks that
its declared terms and its expert do what the docs say."""

import gymnasium as gym
import numpy as np
import pytest

from surgsim_envs.envs import registry
from surgsim_envs.envs.example_task import SPEC, force_error_penalty


@pytest.fixture
def example():
    """Register the example from its spec; afterwards remove it again (other tests read the registry)."""
    registry.register(SPEC)
    try:
        yield SPEC.id
    finally:
        registry.TASKS.pop(SPEC.id, None)
        gym.registry.pop(SPEC.id, None)


def test_force_error_penalty():
    assert force_error_penalty(0.5, 0.5, 1.0) == 0.0
    assert force_error_penalty(0.25, 0.5, 2.0) == -1.0 == force_error_penalty(0.75, 0.5, 2.0)


def test_example_registers_from_its_spec_and_passes_check_env(example):
    from gymnasium.utils.env_checker import check_env

    assert registry.task_spec(example) is SPEC
    env = gym.make(example, **SPEC.quick)
    assert env.spec.max_episode_steps == SPEC.max_episode_steps
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_example_expert_beats_not_pressing(example):
    """Holding the probe above the slab scores -force_weight per step (the whole target missing);
    the expert's presses must do better, and every step's reward is its one declared term."""
    env = gym.make(example)
    returns = {}
    for name, policy in (("hover", lambda obs: np.array([-1.0], dtype=np.float32)),
                         ("expert", registry.expert(example)(env))):
        obs, _ = env.reset(seed=0)
        total, done = 0.0, False
        while not done:
            obs, r, term, trunc, info = env.step(policy(obs))
            assert set(info["reward_terms"]) <= {"force_error", "final"}
            total += r
            done = term or trunc
        returns[name] = total
    env.close()
    assert returns["hover"] == -SPEC.max_episode_steps * 1.0
    assert returns["expert"] > 0.5 * returns["hover"]
