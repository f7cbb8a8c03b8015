"""Spaces that mean something: named observation terms with units and physical bounds, reward
terms in info, max_episode_steps in the registration."""

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs  # noqa: F401
from surgsim_envs.envs import MAX_EPISODE_STEPS, TASKS
from surgsim_envs.envs.registry import task_spec
from surgsim_envs.errors import ConfigError


@pytest.mark.parametrize("task", sorted(TASKS))
def test_names_units_bounds_reward_terms_and_time_limit(task):
    env = gym.make(task, **task_spec(task).quick)
    u = env.unwrapped
    assert env.spec.max_episode_steps == MAX_EPISODE_STEPS[task] == u.max_episode_steps
    names = u.observation_names
    assert len(names) == env.observation_space.shape[0] and len(set(names)) == len(names)
    assert all(n.endswith("]") and " [" in n for n in names)           # "name [unit]" per index
    assert any("[N]" in n for n in names)                               # forces in newtons
    box = env.observation_space
    assert np.all(box.low < box.high) and not np.any(box.low == -1e6)   # no placeholder bounds
    assert np.any(np.isfinite(box.low) & np.isfinite(box.high))         # physical bounds where they exist
    obs, _ = env.reset(seed=0)
    assert box.contains(obs)
    rng = np.random.default_rng(1)
    for _ in range(4):
        obs, reward, term, trunc, info = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
        assert box.contains(obs), [(n, v) for n, v, lo, hi in zip(names, obs, box.low, box.high)
                                   if not lo <= v <= hi]
        terms = info["reward_terms"]
        assert terms and np.isclose(sum(terms.values()), reward, rtol=0, atol=1e-9)
        if term or trunc:
            break
    env.close()


def test_changed_episode_length_with_matching_time_limit_truncates_once_with_its_end_terms():
    env = gym.make("SurgSim/Palpation-v0", episode_seconds=0.1, min_report_seconds=0.1, max_episode_steps=10,
                   **task_spec("SurgSim/Palpation-v0").quick)
    assert env.unwrapped.max_episode_steps == 10
    env.reset(seed=0)
    for k in range(10):
        obs, reward, term, trunc, info = env.step(np.array([0, 0, -1, -1], dtype=np.float32))
    assert trunc and not term and k == 9
    assert "localisation_error_m" in info and "final" in info["reward_terms"]   # the env's own end-of-episode terms


def test_registered_limits_match_the_default_configs():
    from surgsim_envs.envs.registry import TASKS as SPECS

    for task, spec in SPECS.items():
        cfg = spec.config_class()
        # a press task's step is one press; the others' a control period
        steps = cfg.max_presses if hasattr(cfg, "max_presses") else round(cfg.episode_seconds * cfg.control_hz)
        assert MAX_EPISODE_STEPS[task] == spec.max_episode_steps == steps, task
