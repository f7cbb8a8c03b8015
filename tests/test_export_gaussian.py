"""Export of SB3 Gaussian heads to the .npz format: the numpy sampler draws from SB3's
own action distribution. Needs stable-baselines3 + torch (marker ``train``, skipped without)."""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.train
sb3 = pytest.importorskip("stable_baselines3")


@pytest.mark.parametrize("algo", ["PPO", "SAC"])
def test_exported_stochastic_policy_samples_sb3_distribution(algo):
    import gymnasium as gym
    import torch

    from surgsim_envs.integrations.sb3 import check_export, sb3_to_npz

    env = gym.make("Pendulum-v1")
    model = getattr(sb3, algo)("MlpPolicy", env, seed=0, device="cpu", policy_kwargs={"net_arch": [16, 16]})
    with torch.no_grad():              # a non-trivial head: PPO's log_std starts at 0, SAC's layer near 0
        if algo == "PPO":
            model.policy.log_std.fill_(-1.2)
        else:
            model.policy.actor.log_std.bias.fill_(-0.7)
    npz = sb3_to_npz(model, mode="stochastic")
    obs = np.array([[0.3, -0.9, 0.5], [1.0, 0.0, -2.0]], dtype=np.float32)
    assert check_export(model, npz, obs) < 1e-5          # deterministic path, mode restored after
    assert npz.mode == "stochastic"
    torch.manual_seed(0)
    for o in obs:
        ref = np.array([model.predict(o, deterministic=False)[0] for _ in range(3000)], dtype=float)
        ours = np.array([npz(o) for _ in range(3000)], dtype=float)
        # two samples of 3000: means agree within 4 standard errors, sds within 8 %
        se = np.hypot(ref.std(0), ours.std(0)) / np.sqrt(3000)
        assert np.all(np.abs(ref.mean(0) - ours.mean(0)) < 4 * se + 1e-9)
        assert np.allclose(ref.std(0), ours.std(0), rtol=0.08)
    assert ours.std() > 0.05                             # really stochastic
