"""The batched Slippage-v0 vector env (surgsim_envs/batch/slippage_env.py) against the single env.

Where it starts: both envs reset with seed 3 (friction 0.36, pull rate 0.047 N/s), i.e. the settle
(the approach restored from its snapshot, then the jaws closing on the organ tip) has run and the
grasp holds six contact nodes; then a scripted closure (0.70 rising by 0.02 a step) while the
task's pull ramps. The pull starts at once, so the stick/slip chaos window of docs/batch.md opens
early: measured, the observations agree within 9e-5 (forces, N) through control step 6 and depart by
2e-3 N from step 7, so the comparison covers the reset and the first four control steps.

Bounds, carried from the physics bounds of tests/test_batch_slippage_controls.py: opening, wrist
displacement and slip distance within 1e-6 m (float32 tool pose; measured 2e-7 m); per-jaw forces
within 1e-4 of the grip plus 2e-6 N per contact node; the pull, a float64 schedule on the same float64
clock, equal; reward terms (names from ``SlippageEnv.REWARD_TERMS``): ``slip`` within slip_weight x
1e3 x 2 x 1e-6 m (its two slip distances; measured 3.5e-4), ``excess_squeeze`` within squeeze_weight x
the three jaws' force bound, ``hold`` and ``drop`` equal.
"""

import numpy as np
import pytest

from surgsim_envs.batch.backend import available, cuda_available

pytestmark = pytest.mark.skipif(not available(), reason="needs the [batch] extra (warp-lang, mujoco-warp)")

POS = 1e-6                            # m
REL, PER_NODE = 1e-4, 2e-6            # of the grip; N per contact node
STEPS = 4                             # control steps compared (before the chaos window)


def _batched(num_envs, device="cpu"):
    import gymnasium as gym

    return gym.make_vec("SurgSim/Slippage-v0", num_envs=num_envs, vectorization_mode="vector_entry_point",
                        device=device)


def _assert_obs_close(o1, ob, where):
    grip = float(np.sum(o1[1:4]))
    bound = REL * grip + PER_NODE * o1[8]
    assert abs(ob[0] - o1[0]) < POS, (where, "opening")
    assert np.abs(ob[1:7] - o1[1:7]).max() <= bound, (where, "jaw forces", ob[1:7] - o1[1:7], bound)
    assert (ob[7], ob[8]) == (o1[7], o1[8]), (where, "slipping / contact counts")
    assert ob[9] == o1[9], (where, "pull")
    assert abs(ob[10] - o1[10]) < POS and abs(ob[11] - o1[11]) < 2 * POS, (where, "displacement / slip")
    return bound


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda", marks=pytest.mark.skipif(
    not cuda_available(), reason="no CUDA device on this host (Warp sees none)"))])
def test_one_world_follows_the_single_env_through_the_settle_and_the_first_pull_steps(device):
    import gymnasium as gym

    from surgsim_envs.envs.slippage import SlippageEnv

    venv = _batched(1, device)
    single = gym.make("SurgSim/Slippage-v0").unwrapped
    assert venv.single_observation_space == single.observation_space
    assert venv.observation_names == single.observation_names
    assert venv.reward_term_names == tuple(t.name for t in SlippageEnv.REWARD_TERMS)
    o1, i1 = single.reset(seed=3)
    ob, ib = venv.reset(seed=3)
    assert ib["mu"][0] == i1["mu"] and ib["young_scale"][0] == i1["young_scale"]
    assert o1[8] >= 3 and np.sum(o1[1:4]) > 0.2, "the settle must leave a grasp"
    assert o1[9] == 0.0 and o1[10] == 0.0 and o1[11] == 0.0
    _assert_obs_close(o1, ob[0], "reset")
    c = single.config
    moved = 0.0
    for k in range(STEPS):
        a = np.array([0.7 + 0.02 * k], dtype=np.float32)
        o1, r1, te1, tr1, i1 = single.step(a)
        ob, rb, teb, trb, ib = venv.step(a[None])
        bound = _assert_obs_close(o1, ob[0], k)
        assert i1["pull_force_N"] == ib["pull_force_N"][0] > 0.0, k
        t1, tb = i1["reward_terms"], ib["reward_terms"]
        assert abs(tb["slip"][0] - t1["slip"]) <= c.slip_weight * 1e3 * 2 * POS, (k, "slip")
        assert abs(tb["excess_squeeze"][0] - t1["excess_squeeze"]) <= c.squeeze_weight * 3 * bound, k
        assert (tb["hold"][0], tb["drop"][0]) == (t1["hold"], t1["drop"]), k
        assert abs(rb[0] - r1) <= c.slip_weight * 1e3 * 2 * POS + c.squeeze_weight * 3 * bound, k
        assert (teb[0], trb[0]) == (te1, tr1), k
        moved = max(moved, abs(t1["slip"]))
    assert moved > 0.1, "the script must exercise the slip term"


@pytest.mark.slow      # two batched envs, two settles and a third for the reset world: ~8 s
def test_a_world_reset_alone_leaves_the_others_bit_for_bit():
    """Two equally seeded worlds; world 1 restarts (its settle runs while world 0 is held) and
    world 0 goes on exactly as a one-world batch with the same seed and actions."""
    pair, one = _batched(2), _batched(1)
    pair.reset(seed=[3, 3])
    one.reset(seed=3)
    a = np.array([[0.8]], dtype=np.float32)
    for k in range(4):
        if k == 2:
            pair.unwrapped._reset_worlds(np.array([1]), {})        # the autoreset path for one world
            assert pair.unwrapped._steps[1] == 0
            np.testing.assert_array_equal(pair.unwrapped._observe()[0], op[0])   # world 0 reads as before
        op, *_ = pair.step(np.repeat(a, 2, axis=0))
        oo, *_ = one.step(a)
        np.testing.assert_array_equal(op[0], oo[0], err_msg=f"step {k}")
    np.testing.assert_array_equal(pair.unwrapped.sim.tissue_positions()[0], one.unwrapped.sim.tissue_positions()[0])
    assert not np.array_equal(op[1], op[0]), "world 1 restarted its episode"
