"""Slippage-v0's settle replays its contact-free approach from a snapshot (scene/approach_snapshot.py):
the rigid state it restores is the full run's bit for bit, the settled grasp is the full settle's
up to round-off, resets do not depend on history, and nothing is kept where the tissue moves."""

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import surgsim_envs  # noqa: F401
from surgsim_envs.envs.slippage import no_pull
from surgsim_envs.errors import ConfigError
from surgsim_envs.scene.approach_snapshot import ApproachSnapshot

SPEC = mujoco.mjtState.mjSTATE_INTEGRATION


def _state(sim) -> np.ndarray:
    out = np.empty(mujoco.mj_stateSize(sim.model, SPEC))
    mujoco.mj_getState(sim.model, sim.data, out, SPEC)
    return out


def _settle_key(u):
    steps = int(round(u.config.settle_time / u.sim.dt))
    return ("settle", u._closure_ctrl(u.config.initial_closure), steps), steps


@pytest.fixture(scope="module")
def replayed():
    env = gym.make("SurgSim/Slippage-v0")
    env.reset(seed=3)
    yield env
    env.close()


def test_the_snapshot_is_the_full_runs_rigid_state_before_any_contact(replayed):
    u = replayed.unwrapped
    key, steps = _settle_key(u)
    kept = u._approach.steps_kept(u.sim, key)
    assert 0.3 * steps <= kept < steps                      # about half the settle is travel through air
    snap = u._approach._kept[u.sim][key]
    sim, goal = u.sim, key[1]
    sim.reset()
    rest = sim.tissue().positions.copy()
    first_contact = None
    for k in range(1, steps + 1):                           # the full approach, one step at a time
        u._run(1, goal, no_pull)
        if k == kept:
            assert np.array_equal(_state(sim), snap.state)  # bit for bit: time, qpos, qvel, warm start, ctrl, ...
            assert sim.steps == snap.steps == k
        if np.any(sim.contacts[next(iter(sim.contacts))].result.forces != 0.0):
            first_contact = k
            break
        assert np.abs(sim.tissue().positions - rest).max() < 1e-12   # untouched tissue stays at rest
    assert first_contact is not None and kept + u._approach.margin_steps <= first_contact


def test_the_replayed_settle_is_the_full_settle_up_to_round_off(replayed):
    full = gym.make("SurgSim/Slippage-v0", replay_approach=False)
    for seed in (11, 12):
        o_full, i_full = full.reset(seed=seed)
        o_rep, i_rep = replayed.reset(seed=seed)
        a, b = full.unwrapped, replayed.unwrapped
        assert (a.mu, a.young_scale) == (b.mu, b.young_scale)
        assert np.abs(a.sim.tissue().positions - b.sim.tissue().positions).max() < 1e-12    # m
        assert np.abs(a.sim.tissue().velocities - b.sim.tissue().velocities).max() < 1e-9   # m/s
        assert np.array_equal(a.slip.nodes, b.slip.nodes)
        assert a.sim.time == b.sim.time and a.sim.steps == b.sim.steps
        np.testing.assert_allclose(o_rep, o_full, rtol=0, atol=1e-6)
    full.close()


@pytest.mark.slow          # 37 s (two FEM settles); the spleen tests above stay in the default run
def test_on_another_organ_closure_and_model_the_replay_still_matches():
    """Parameters the snapshot was not designed on: the liver lobe, a tighter closure, a coarse
    lattice and the FEM tissue (its first contact, and so the steps kept, differ from the spleen's)."""
    opts = dict(organ="liver_lobe", initial_closure=0.9, resolution=0.015, model="fem")
    rep = gym.make("SurgSim/Slippage-v0", **opts)
    full = gym.make("SurgSim/Slippage-v0", replay_approach=False, **opts)
    o_rep, _ = rep.reset(seed=21)
    o_full, _ = full.reset(seed=21)
    u = rep.unwrapped
    key, steps = _settle_key(u)
    assert 0 < u._approach.steps_kept(u.sim, key) < steps
    assert np.abs(u.sim.tissue().positions - full.unwrapped.sim.tissue().positions).max() < 1e-12
    assert np.array_equal(u.slip.nodes, full.unwrapped.slip.nodes)
    np.testing.assert_allclose(o_rep, o_full, rtol=0, atol=1e-6)
    rep.close()
    full.close()


def test_a_reset_does_not_depend_on_the_episodes_before_it():
    fresh = gym.make("SurgSim/Slippage-v0")
    used = gym.make("SurgSim/Slippage-v0")
    used.reset(seed=1)
    for _ in range(5):
        used.step(np.array([0.5], dtype=np.float32))
    o_used, _ = used.reset(seed=7)
    o_fresh, _ = fresh.reset(seed=7)            # this one records the snapshot in this very reset
    assert np.array_equal(o_used, o_fresh)
    assert np.array_equal(used.unwrapped.sim.tissue().positions, fresh.unwrapped.sim.tissue().positions)
    assert np.array_equal(_state(used.unwrapped.sim), _state(fresh.unwrapped.sim))
    fresh.close()
    used.close()


def test_nothing_is_kept_past_a_tissue_that_moved(replayed):
    u = replayed.unwrapped
    sim, goal = u.sim, _settle_key(u)[0][1]
    chunks = []

    def run(n):                                  # the approach, with the tissue nudged in the 3rd chunk
        chunks.append(n)
        if len(chunks) == 3:
            sim.tissue().velocities[:, 2] += 1e-3     # every node (some are pinned)
        u._run(n, goal, no_pull)

    for margin, expected in ((0, 20), (50, 0)):
        chunks.clear()
        sim.reset()
        snap = ApproachSnapshot(margin_steps=margin, chunk_steps=10)
        assert snap.skip(sim, "nudged", run, 1000) == expected
        assert len(chunks) == 3                   # recording stopped at the motion
        assert snap.steps_kept(sim, "nudged") == expected
    sim.reset()
    assert np.all(sim.tissue().velocities == 0.0)  # the record left the simulation at its reset state


def test_bad_settings_are_refused_with_the_value():
    with pytest.raises(ConfigError, match="replay_approach='yes'"):
        gym.make("SurgSim/Slippage-v0", replay_approach="yes")
    with pytest.raises(ConfigError, match="margin_steps=-1"):
        ApproachSnapshot(margin_steps=-1)
    with pytest.raises(ConfigError, match="chunk_steps=0"):
        ApproachSnapshot(chunk_steps=0)
    with pytest.raises(ConfigError, match="tolerance_m=nan"):
        ApproachSnapshot(tolerance_m=float("nan"))
