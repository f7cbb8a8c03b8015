"""The batched Palpation-v0 vector env (surgsim_envs/batch/palpation_env.py) against the single env.

``gym.make_vec(..., vectorization_mode="vector_entry_point", device="cpu")`` returns the batched
env; with one world and the same seed it follows ``gym.make("SurgSim/Palpation-v0",
model="mass_spring", spacing=0.01)`` (the model and lattice the batched kernels step) through a
scripted episode (a stationary press, then a held report). Its physics agrees
to the bounds of tests/test_batch_equivalence.py (tool 1e-6 m, force 1e-4 relative); the
observations and rewards inherit them: positions to 1e-6 m, forces and stiffness samples to 1e-4
relative, the stiffness-weighted estimate (cubic in the samples' excess over their median) to
1e-5 m, rewards to 1e-3 (measured: 3e-5), the episode ends at the same step.
"""

import numpy as np
import pytest

from surgsim_envs.batch.backend import available

#: the single env the batched worlds are (the model and lattice the batched kernels step)
BATCHED = {"model": "mass_spring", "spacing": 0.01}

pytestmark = pytest.mark.skipif(not available(), reason="needs the [batch] extra (warp-lang, mujoco-warp)")

SHORT = dict(episode_seconds=0.5, min_report_seconds=0.0)      # 50 control steps, report allowed at once


def _action(k):
    """Move, press still for 8 steps (quasi-static samples from the 5th), lift and hold report."""
    if k < 4:
        return [1.0, 0.5, -1.0, -1.0]
    if k < 12:
        return [0.0, 0.0, 0.6, -1.0]
    return [0.0, 0.0, -1.0, 1.0]


def _batched(num_envs, **kwargs):
    import gymnasium as gym

    return gym.make_vec("SurgSim/Palpation-v0", num_envs=num_envs, vectorization_mode="vector_entry_point",
                        device="cpu", max_episode_steps=50, **SHORT, **kwargs)


@pytest.fixture(scope="module")
def venv():
    return _batched(2)


def test_make_vec_with_device_returns_the_batched_env(venv):
    import gymnasium as gym

    from surgsim_envs.batch.palpation_env import BatchedPalpationEnv

    single = gym.make("SurgSim/Palpation-v0", **BATCHED)
    assert isinstance(venv, BatchedPalpationEnv)
    assert venv.single_observation_space == single.observation_space
    assert venv.single_action_space == single.action_space
    assert venv.observation_names == single.unwrapped.observation_names
    assert venv.observation_space.shape == (2,) + single.observation_space.shape


def test_one_world_follows_the_single_env_through_an_episode():
    import gymnasium as gym

    venv = _batched(1)
    env = gym.make("SurgSim/Palpation-v0", max_episode_steps=50, **SHORT, **BATCHED)
    ob, info = venv.reset(seed=3)
    o1, i1 = env.reset(seed=3)
    np.testing.assert_array_equal(info["inclusion_centre_m"][0], i1["inclusion_centre_m"])
    np.testing.assert_array_equal(ob[0], o1)
    sampled = 0.0
    for k in range(50):
        a = np.array(_action(k), dtype=np.float32)
        ob, r, te, tr, _ = venv.step(a[None])
        o1, r1, te1, tr1, i1 = env.step(a)
        o, f = ob[0].astype(float), o1.astype(float)
        np.testing.assert_allclose(o[0:3], f[0:3], rtol=0, atol=1e-6, err_msg=f"tool position, step {k}")
        np.testing.assert_allclose(o[3:6], f[3:6], rtol=0, atol=1e-4 * np.linalg.norm(f[3:6]) + 1e-6,
                                   err_msg=f"contact force, step {k}")
        np.testing.assert_allclose(o[[6, 7, 8, 10]], f[[6, 7, 8, 10]], rtol=0, atol=1e-6, err_msg=f"step {k}")
        np.testing.assert_allclose(o[[9, 13]], f[[9, 13]], rtol=1e-4, err_msg=f"stiffness terms, step {k}")
        np.testing.assert_allclose(o[11:13], f[11:13], rtol=0, atol=1e-5, err_msg=f"estimate, step {k}")
        np.testing.assert_allclose(o[14:], f[14:], rtol=0, atol=1e-4, err_msg=f"stiffness map, step {k}")
        assert abs(r[0] - r1) < 1e-3, (k, r[0], r1)
        assert (te[0], tr[0]) == (te1, tr1), k
        sampled = max(sampled, f[9])
        if te1 or tr1:
            break
    assert te1 and k == 16, "the report held for 5 steps ends the episode at step 16"
    assert sampled > 10.0, "the presses must take stiffness samples (N/m)"


def test_autoreset_next_step_resets_only_the_finished_world(venv):
    ob, _ = venv.reset(seed=11)
    first = ob.copy()
    for k in range(5):
        a = np.array([[0.0, 0.0, -1.0, 1.0], [0.0, 0.0, -1.0, -1.0]], dtype=np.float32)
        ob, r, te, tr, info = venv.step(a)
        if te[0]:
            break
    assert te[0] and not te[1] and not tr[1]
    assert info["_success"][0] and not info["_success"][1]
    ob, r, te, tr, _ = venv.step(np.zeros((2, 4), dtype=np.float32))
    assert r[0] == 0.0 and not te[0] and not tr[0]
    assert k == 4, "report held from the first step ends world 0's episode at its 5th step"
    assert ob[0, 10] == 0.0 and ob[1, 10] == pytest.approx(6 / 50)     # episode fraction
    # world 0 starts a new episode from its own generator: a new inclusion, same home position
    np.testing.assert_allclose(ob[0, 0:3], first[0, 0:3], atol=1e-7)


def test_device_arrays_are_shared_through_dlpack(venv):
    venv.reset(seed=0)
    venv.step(np.zeros((2, 4), dtype=np.float32))
    arr = venv.device_arrays()["tissue_positions"]
    shared = np.from_dlpack(arr)
    assert shared.shape == (2, venv.sim.topology.n_nodes, 3)
    np.testing.assert_array_equal(shared, venv.sim.tissue_positions())
    assert np.shares_memory(shared, np.from_dlpack(arr))


def test_bad_vector_arguments_raise_clear_errors(venv):
    import gymnasium as gym

    from surgsim_envs.errors import ConfigError

    with pytest.raises(ConfigError, match=r"device= \(the batched Warp backend\) is available for"):
        gym.make_vec("SurgSim/PalpationPress-v0", num_envs=2, vectorization_mode="vector_entry_point", device="cpu")
    with pytest.raises(ConfigError, match=r"actions must be finite \(2, 4\) numbers"):
        venv.step(np.zeros((3, 4)))
    with pytest.raises(ConfigError, match="unknown reset option"):
        venv.reset(options={"colour": 1})
