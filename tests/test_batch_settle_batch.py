"""Slippage-v0's reset settle (510-520 physics steps of jaw closure) for a few worlds runs in a small batch
of the same scene and is copied in (``BatchSimulation.copy_worlds_from``), so the other worlds do not
step: it must give what settling them in the batch itself, the others held, gives, bit for bit."""

import numpy as np
import pytest

from surgsim_envs.batch.backend import available
from surgsim_envs.errors import ConfigError

pytestmark = pytest.mark.skipif(not available(), reason="needs the [batch] extra (warp-lang, mujoco-warp)")

W = 5
TASK = dict(control_hz=125.0, episode_seconds=0.2, closing_speed=0.5, settle_time=0.1, pull_rate=(0.5, 1.0))


def _env(device_outputs=False):
    from gymnasium.envs.registration import load_env_creator

    from surgsim_envs.envs import BATCHED

    return load_env_creator(BATCHED["SurgSim/Slippage-v0"])(W, device="cpu", device_outputs=device_outputs, **TASK)


@pytest.mark.parametrize("device_outputs", [False, True])
@pytest.mark.slow
def test_a_few_worlds_settle_in_a_small_batch_as_in_the_batch_itself(device_outputs):
    small, inside = _env(device_outputs), _env(device_outputs)
    inside._settle_batch = lambda k: None          # the settle in the batch itself, the other worlds held
    rng = np.random.default_rng(4)
    for env in (small, inside):
        env.reset(seed=0)
    for step in range(8):
        if step in (2, 5):
            mask = np.zeros(W, dtype=bool)
            mask[[1] if step == 2 else [0, 2, 4]] = True
            got = [env.reset(seed=step, options={"reset_mask": mask})[0] for env in (small, inside)]
            np.testing.assert_array_equal(np.array(got[0]), np.array(got[1]), err_msg=f"reset at step {step}")
        a = rng.uniform(-1, 1, (W, 1))
        out = [env.step(a)[:4] for env in (small, inside)]
        for x, y in zip(*out):
            np.testing.assert_array_equal(np.array(x), np.array(y), err_msg=f"step {step}")
    rows_small, rows_inside = small.sim.world_rows(), inside.sim.world_rows()
    for name in ("tissue.x", "tissue.v", "contact.state", "contact.anchor", "fields.K1", "contact.mu", "data.qpos",
                 "data.qvel", "data.qacc_warmstart", "tools.ctrl64"):
        np.testing.assert_array_equal(rows_small[name].numpy(), rows_inside[name].numpy(), err_msg=name)
    np.testing.assert_array_equal(small._clock, inside._clock)
    assert sorted(small._settle_batches) == [1, 4]            # one world, then three (a batch of four)
    assert small.sim.steps < inside.sim.steps                 # the small batch took the settles' steps
    small.close()
    inside.close()


def test_copy_worlds_from_checks_its_arguments():
    env = _env()
    env.reset(seed=0)
    sim = env.sim
    with pytest.raises(ConfigError, match=r"src_worlds and dst_worlds must be as many indices in \[0, 5\) and "
                                          r"\[0, 5\), got \[0, 1\] and \[2\]"):
        sim.copy_worlds_from(sim, [0, 1], [2])
    with pytest.raises(ConfigError, match=r"got \[7\] and \[2\]"):
        sim.copy_worlds_from(sim, [7], [2])
    from gymnasium.envs.registration import load_env_creator

    from surgsim_envs.envs import BATCHED

    other = load_env_creator(BATCHED["SurgSim/Palpation-v0"])(1, device="cpu")
    with pytest.raises(ConfigError, match=r"copy_worlds_from needs a batch of the same scene"):
        sim.copy_worlds_from(other.sim, [0], [2])
    before = sim.tissue_positions()
    sim.copy_worlds_from(sim, [0], [3])                    # a world's whole state into another
    after = sim.tissue_positions()
    np.testing.assert_array_equal(after[3], before[0])
    np.testing.assert_array_equal(after[[0, 1, 2, 4]], before[[0, 1, 2, 4]])
    other.close()
    env.close()
