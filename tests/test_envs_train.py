"""stable-baselines3's env checker on every task (runs only with the [train] extra: pytest -m train)."""

import pytest

pytestmark = pytest.mark.train


@pytest.mark.parametrize("env_id", ["SurgSim/Palpation-v0", "SurgSim/Grasp-v0", "SurgSim/Slippage-v0"])
def test_sb3_check_env(env_id):
    pytest.importorskip("stable_baselines3")
    import gymnasium as gym
    from stable_baselines3.common.env_checker import check_env

    import surgsim_envs  # noqa: F401

    env = gym.make(env_id)
    check_env(env.unwrapped, warn=True)
    env.close()
