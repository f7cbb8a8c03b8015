"""The Gaussian head of the .npz policy format: stochastic actions from a seeded numpy
sampler, with the distribution the file records (numpy only)."""

from __future__ import annotations

import numpy as np
import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.policies.npz_policy import NpzPolicy

RNG = np.random.default_rng(7)
W0, B0 = RNG.normal(size=(4, 6)), RNG.normal(size=6)
W1, B1 = RNG.normal(size=(6, 2)) * 0.3, RNG.normal(size=2) * 0.1
OBS = np.array([0.3, -0.2, 0.5, 0.1])
N = 4000          # samples; the mean of N draws has sd sigma / sqrt(N)


def hidden(obs):
    return np.tanh(obs @ W0 + B0)


def ppo_like(mode="stochastic", seed=0):
    """Constant log sd, identity output, clipped to wide bounds (never active here)."""
    return NpzPolicy([W0, W1], [B0, B1], activation="tanh", log_std=np.array([-1.0, -2.0]),
                     action_low=-50.0, action_high=50.0, mode=mode, seed=seed)


def sac_like(mode="stochastic", seed=0, log_std_max=2.0):
    """State-dependent log sd layer, tanh squashing scaled to [0, 4] x [-1, 1]."""
    lw, lb = RNG.normal(size=(6, 2)) * 0.2, np.array([-1.5, 5.0])
    low, high = np.array([0.0, -1.0]), np.array([4.0, 1.0])
    p = NpzPolicy([W0, W1], [B0, B1], activation="tanh", output_activation="tanh", log_std_W=lw, log_std_b=lb,
                  log_std_max=log_std_max, action_scale=(high - low) / 2, action_bias=(high + low) / 2,
                  action_low=low, action_high=high, mode=mode, seed=seed)
    return p, lw, lb


def test_constant_log_std_samples_the_recorded_gaussian():
    p = ppo_like()
    mean = hidden(OBS) @ W1 + B1
    a = np.stack([p(OBS) for _ in range(N)]).astype(float)
    sd = np.exp([-1.0, -2.0])
    assert np.all(np.abs(a.mean(0) - mean) < 4 * sd / np.sqrt(N))
    assert np.allclose(a.std(0), sd, rtol=0.05)
    det = ppo_like(mode="deterministic")
    assert np.allclose(det(OBS), mean, atol=1e-6)


def test_state_dependent_log_std_with_tanh_squashing_and_its_clip():
    p, lw, lb = sac_like(log_std_max=0.5)
    h = hidden(OBS)
    mean, log_sd = h @ W1 + B1, np.clip(h @ lw + lb, -20.0, 0.5)
    assert log_sd[1] == 0.5                     # the clip is active on the second action
    a = np.stack([p(OBS) for _ in range(N)]).astype(float)
    pre = np.arctanh(np.clip((a - p.action_bias) / p.action_scale, -1 + 1e-6, 1 - 1e-6))
    assert np.all(np.abs(pre.mean(0) - mean) < 4 * np.exp(log_sd) / np.sqrt(N) + 2e-3)
    assert np.allclose(pre.std(0), np.exp(log_sd), rtol=0.06)
    assert np.all(a >= p.action_low) and np.all(a <= p.action_high)


def test_reset_seed_makes_episodes_reproducible():
    p = ppo_like(seed=3)
    first = [p(OBS) for _ in range(5)]
    p.reset(3)
    assert np.array_equal(first, [p(OBS) for _ in range(5)])
    p.reset(4)
    assert not np.array_equal(first, [p(OBS) for _ in range(5)])


def test_mode_and_head_survive_save_and_load(tmp_path):
    p, lw, _ = sac_like()
    path = p.save(tmp_path / "sac.npz")
    q = NpzPolicy.load(path, seed=11)
    assert q.mode == "stochastic" and np.array_equal(q.log_std_W, lw) and q.log_std_max == 2.0
    p.reset(11)
    assert np.array_equal([p(OBS) for _ in range(3)], [q(OBS) for _ in range(3)])
    assert NpzPolicy.load(path, mode="deterministic").mode == "deterministic"
    det = NpzPolicy.load(path, mode="deterministic")
    assert np.array_equal(det(OBS), det(OBS))


def test_bad_gaussian_heads_are_config_errors():
    with pytest.raises(ConfigError, match="needs a Gaussian head"):
        NpzPolicy([W0, W1], [B0, B1], mode="stochastic")
    with pytest.raises(ConfigError, match="mode 'sometimes' unknown"):
        ppo_like(mode="sometimes")
    with pytest.raises(ConfigError, match="log_std_W and log_std_b come together"):
        NpzPolicy([W0, W1], [B0, B1], log_std_W=np.zeros((6, 2)))
    with pytest.raises(ConfigError, match=r"log_std_W must have shape \(6, 2\)"):
        NpzPolicy([W0, W1], [B0, B1], log_std_W=np.zeros((4, 2)), log_std_b=np.zeros(2))
    with pytest.raises(ConfigError, match="not both"):
        NpzPolicy([W0, W1], [B0, B1], log_std=np.zeros(2), log_std_W=np.zeros((6, 2)), log_std_b=np.zeros(2))
    with pytest.raises(ConfigError, match="log_std holds NaN"):
        NpzPolicy([W0, W1], [B0, B1], log_std=np.array([0.0, np.nan]))
    with pytest.raises(ConfigError, match="needs a Gaussian head"):
        NpzPolicy([W0, W1], [B0, B1]).with_mode("stochastic")


def test_sampler_stream_is_not_the_env_stream_of_the_same_seed():
    """Gymnasium seeds env.np_random as default_rng(seed); a policy reset with the same seed must
    not replay it (the action noise would then encode the env's randomisation)."""
    p = ppo_like(seed=0)
    p.reset(10001)
    noise = p.rng.standard_normal(64)
    assert not np.allclose(noise, np.random.default_rng(10001).standard_normal(64))
    assert abs(np.corrcoef(noise, np.random.default_rng(10001).standard_normal(64))[0, 1]) < 0.5


def test_noise_scale_is_a_temperature_on_the_sd_and_is_saved(tmp_path):
    p = NpzPolicy([W0, W1], [B0, B1], activation="tanh", log_std=np.array([-1.0, -2.0]), mode="stochastic",
                  noise_scale=0.5)
    a = np.stack([p(OBS) for _ in range(N)]).astype(float)
    assert np.allclose(a.std(0), 0.5 * np.exp([-1.0, -2.0]), rtol=0.05)
    assert NpzPolicy.load(p.save(tmp_path / "t.npz")).noise_scale == 0.5
    assert NpzPolicy.load(tmp_path / "t.npz", noise_scale=0.0)(OBS).tolist() == \
        NpzPolicy.load(tmp_path / "t.npz", mode="deterministic")(OBS).tolist()
    with pytest.raises(ConfigError, match="noise_scale=-1 must be"):
        NpzPolicy([W0, W1], [B0, B1], log_std=np.zeros(2), noise_scale=-1)


def test_scenario_rollout_reseeds_a_stochastic_policy_per_episode(tmp_path):
    """`surgsim run` with a stochastic .npz: each episode's sampler is reseeded with the episode's
    reset seed (scenario seed + episode), so episode 1 of a seed-5 run (reset seed 6) repeats
    episode 0 of a seed-6 run press for press (a sampler seeded once per run would not)."""
    from surgsim_envs.envs.registry import load_shipped
    from surgsim_envs.scenarios.rollout import run_rollout
    from surgsim_envs.scenarios.loader import loads_scenario

    load_shipped("SurgSim/PalpationPress-v0").save(tmp_path / "press.npz")
    assert NpzPolicy.load(tmp_path / "press.npz").mode == "stochastic"

    def presses(seed):
        text = (f'[scenario]\nname = "reseed"\ntask = "SurgSim/PalpationPress-v0"\nseed = {seed}\n'
                '[policy]\nfile = "press.npz"\nepisodes = 2\nmax_steps = 2\n')
        return run_rollout(loads_scenario(text, folder=tmp_path)).recording.position

    five, six = presses(5), presses(6)
    assert five.shape == (4, 3)
    assert np.array_equal(five[2:], six[:2])
    assert not np.allclose(five[:2], six[:2])


def test_act_batch_is_the_per_observation_policy():
    """act_batch on k observations = __call__ row by row (deterministic: to float32 rounding; SAC's squashed,
    clipped head included); stochastic: one noise row per observation, the batch mean of many copies of one
    observation is the deterministic action; .batched pickles and keeps reset(seed)."""
    import pickle

    obs = np.random.default_rng(3).normal(size=(6, 4))
    for p in (ppo_like("deterministic"), sac_like("deterministic")[0]):
        a = p.act_batch(obs)
        assert a.shape == (6, 2) and a.dtype == np.float32
        np.testing.assert_allclose(a, np.stack([p(o) for o in obs]), rtol=0, atol=1e-6)
    p = ppo_like("stochastic", seed=1)
    many = p.act_batch(np.tile(OBS, (N, 1)))
    det = ppo_like("deterministic")(OBS)
    assert many.std(axis=0)[0] > 0.3                               # sd exp(-1) = 0.37: rows differ
    np.testing.assert_allclose(many.mean(axis=0), det, atol=4 * np.exp(-1.0) / np.sqrt(N))
    b = pickle.loads(pickle.dumps(ppo_like("stochastic").batched))
    b.reset(5)
    first = b(obs)
    b.reset(5)
    assert np.array_equal(first, b(obs))
    with pytest.raises(ConfigError, match=r"act_batch expects observations of shape \(k, 4\), got \(4,\)"):
        p.act_batch(OBS)
    with pytest.raises(ConfigError, match="NaN or inf"):
        p.act_batch(np.full((2, 4), np.nan))
