"""``reset(options={"reset_mask": mask})`` of the batched envs (Gymnasium's vector-env convention): only
the masked worlds start a new episode, seeded as in a full reset; the others keep theirs."""

import numpy as np
import pytest

from surgsim_envs.batch.backend import available
from surgsim_envs.errors import ConfigError

pytestmark = pytest.mark.skipif(not available(), reason="needs the [batch] extra (warp-lang, mujoco-warp)")

W = 3
SHORT = dict(episode_seconds=0.3, min_report_seconds=0.05)


def _env(**kw):
    from gymnasium.envs.registration import load_env_creator

    from surgsim_envs.envs import BATCHED

    return load_env_creator(BATCHED["SurgSim/Palpation-v0"])(W, device="cpu", **SHORT, **kw)


@pytest.mark.parametrize("device_outputs", [False, True])
def test_masked_worlds_restart_seeded_and_the_others_keep_their_episodes(device_outputs):
    env, fresh = _env(device_outputs=device_outputs), _env(device_outputs=device_outputs)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(4):
        obs, *_ = env.step(rng.uniform(-1, 1, (W, 4)))
    before = np.array(obs)
    mask = np.array([False, True, False])
    obs, info = env.reset(seed=10, options={"reset_mask": mask})
    obs = np.array(obs)
    ref_obs, ref_info = fresh.reset(seed=10)
    np.testing.assert_array_equal(obs[1], np.array(ref_obs)[1])          # world 1: seed 10 + 1, from rest
    np.testing.assert_array_equal(info["inclusion_centre_m"][1], ref_info["inclusion_centre_m"][1])
    np.testing.assert_array_equal(obs[[0, 2]], before[[0, 2]])           # the others did not move
    assert not np.array_equal(info["inclusion_centre_m"][0], ref_info["inclusion_centre_m"][0])
    np.testing.assert_array_equal(info["_inclusion_centre_m"], mask)
    # the restarted world steps on as the fresh env's world 1 does
    a = rng.uniform(-1, 1, (W, 4))
    o1, r1, *_ = env.step(a)
    o2, r2, *_ = fresh.step(a)
    np.testing.assert_array_equal(np.array(o1)[1], np.array(o2)[1])
    np.testing.assert_array_equal(np.array(r1)[1], np.array(r2)[1])
    env.close()
    fresh.close()


def test_a_masked_reset_clears_a_pending_autoreset_and_bad_masks_are_named():
    env = _env()
    env.reset(seed=0)
    press = np.tile([0.0, 0.0, 1.0, 1.0], (W, 1))          # report at once: episodes end after the hold
    steps = 0
    while True:
        _, _, term, trunc, _ = env.step(press)
        steps += 1
        if (term | trunc).any() or steps > 60:
            break
    ended = term | trunc
    assert ended.any()
    env.reset(options={"reset_mask": ended})
    _, reward, term, trunc, info = env.step(np.zeros((W, 4)))
    assert np.all(info["steps"][ended] == 1), "a masked reset starts the episode: no autoreset on the next step"
    for bad, what in ((np.array([1, 0, 0]), "int64"), ([True, False, False], "list"),
                      (np.zeros(W, dtype=bool), "bool"), (np.ones(W + 1, dtype=bool), "bool")):
        with pytest.raises(ConfigError, match=r"options\['reset_mask'\] must be a numpy bool array of shape \(3,\) "
                                              rf"with at least one True \(the worlds to reset\), got .*{what}"):
            env.reset(options={"reset_mask": bad})
    env.close()
