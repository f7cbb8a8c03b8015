"""stable-baselines3's env checker on every task (runs only with the [train] extra: pytest -m train)."""

import pytest

from surgsim_envs.envs import TASKS

pytestmark = pytest.mark.train


@pytest.mark.parametrize("env_id", sorted(TASKS))    # every physics-rate task of the registry
def test_sb3_check_env(env_id):
    pytest.importorskip("stable_baselines3")
    import gymnasium as gym
    from stable_baselines3.common.env_checker import check_env

    import surgsim_envs  # noqa: F401

    env = gym.make(env_id)
    check_env(env.unwrapped, warn=True)
    env.close()
