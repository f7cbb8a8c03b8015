"""SB3VectorEnv (surgsim_envs/integrations/sb3.py): stable-baselines3 on the shared-memory vector
env gives what SB3's own make_vec_env + DummyVecEnv gives for the same seed: observations,
rewards, dones, terminal observations, TimeLimit.truncated, Monitor's episode records; and
get_attr/set_attr/env_method with indices reach the right envs."""

from __future__ import annotations

import numpy as np
import pytest

sb3 = pytest.importorskip("stable_baselines3", reason="SB3VectorEnv needs the [train] extra (stable-baselines3)")

from test_vector_env import Toy  # noqa: E402


def test_sb3_vector_env_matches_dummy_vec_env():
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv

    from surgsim_envs.integrations.sb3 import make_sb3_vec_env

    ours = make_sb3_vec_env(Toy, 3, seed=4, workers=2)
    ref = make_vec_env(Toy, n_envs=3, seed=4, vec_env_cls=DummyVecEnv)
    try:
        assert np.array_equal(ours.reset(), ref.reset())
        rng = np.random.default_rng(0)
        episodes = 0
        for k in range(40):
            a = rng.uniform(-1, 1, (3, 2)).astype(np.float32)
            r1, r2 = ours.step(a), ref.step(a)
            for x, y in zip(r1[:3], r2[:3]):
                assert x.dtype == y.dtype and np.array_equal(x, y), k
            for d1, d2 in zip(r1[3], r2[3]):
                assert ("terminal_observation" in d1) == ("terminal_observation" in d2)
                if "terminal_observation" in d2:
                    episodes += 1
                    assert np.array_equal(d1["terminal_observation"], d2["terminal_observation"])
                    assert d1["TimeLimit.truncated"] == d2["TimeLimit.truncated"]
                    # VecMonitor keeps float32 returns, Monitor rounds to 6 decimals
                    assert d1["episode"]["l"] == d2["episode"]["l"]
                    assert d1["episode"]["r"] == pytest.approx(d2["episode"]["r"], abs=1e-5)
        assert episodes >= 5
        assert ours.get_attr("horizon", indices=[2, 0]) == [7, 7]
        ours.set_attr("horizon", 3, indices=[1])
        assert ours.get_attr("horizon") == [7, 3, 7]
        assert ours.env_method("get_wrapper_attr", "hang_at", indices=[1]) == [None]
    finally:
        ours.close()
        ref.close()
