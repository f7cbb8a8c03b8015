"""Slippage-v0's device path (``device_outputs=True``: batch/slippage_kernels.py) against its numpy
path (the default), 3 worlds on Warp's CPU device.

Both envs step the same physics kernels, so what is compared is the task's part: the control
schedule (jaw and pull per MuJoCo step, a Warp kernel on the device path, the compiled numba
schedule on the host path) and the bookkeeping. Over 14 control steps of a fixed script (seed 7;
0.08 s episodes at 125 Hz, 10 control steps of 20 physics steps; a 0.1 s settle with fast jaws, a
steep 0.5-1 N/s pull and a 4 mm loss-of-grasp slip, so that episodes end within the file's time):
world 0 squeezes hard and holds until the time limit (truncated, success); world 1 grips loosely
and the organ slips out past ``max_slip`` (lost: terminated, drop); world 2 opens its jaws until
no contact is left (lost); each end is followed by a NEXT_STEP autoreset (the settle on the host,
the episode's start on the device).
Every observation, reward, reward term, terminated/truncated flag, info entry and the controls
the schedule wrote are equal exactly: no bound is needed, because the kernels do the host's
arithmetic in the host's order (``np.sum`` of the jaw forces in order, BLAS's in-order dot for the
slip norm and the wrist displacement, the centroid's rows added in node order then divided by the
count, Python's ``max(0.0, x)``, the C library's ``sin`` as numba calls it, Python's ``sum`` of the
terms), compiled without floating-point contraction, and no operation in the chain goes through a
numpy SIMD kernel whose result depends on the CPU's features (checked with
``NPY_DISABLE_CPU_FEATURES`` set: equal too).

The scripted run takes about a minute on Warp's CPU device, so it runs under ``-m slow``; the default
run keeps the checks that need no script (DLPack sharing, argument errors). Palpation-v0's device path
(tests/test_batch_device_terms.py) is the default run's representative of the comparison.
"""

import numpy as np
import pytest

from surgsim_envs.batch.backend import available

pytestmark = pytest.mark.skipif(not available(), reason="needs the [batch] extra (warp-lang, mujoco-warp)")

W = 3
STEPS = 14
HZ, EPISODE = 125.0, 0.08
#: 10-step episodes at 125 Hz, fast jaws and a short settle (an opening world loses its contacts within
#: a few steps; a reset costs ~1/4 of the default's), a steep pull and a 4 mm loss-of-grasp slip
TASK = dict(control_hz=HZ, episode_seconds=EPISODE, closing_speed=0.5, settle_time=0.1, pull_rate=(0.5, 1.0),
            max_slip=0.004)
OPEN_AT = 2          # world 2 opens its jaws at this step of its first episode


def _make(device_outputs):
    import gymnasium as gym

    return gym.make_vec("SurgSim/Slippage-v0", num_envs=W, vectorization_mode="vector_entry_point", device="cpu",
                        max_episode_steps=int(round(EPISODE * HZ)), device_outputs=device_outputs, **TASK)


def _actions(t_episode, episodes):
    """World 0: squeeze hard; world 1: a loose grip in its first episode; world 2: open from
    ``OPEN_AT`` in its first episode; after a first episode every world squeezes hard."""
    a = np.ones((W, 1))
    if episodes[1] == 0:
        a[1] = 0.0
    if episodes[2] == 0 and t_episode[2] >= OPEN_AT:
        a[2] = -1.0
    return a.astype(np.float32)


def _host(x):
    return x.numpy().copy() if hasattr(x, "numpy") and not isinstance(x, np.ndarray) else np.array(x)


def _host_info(info):
    return {k: ({n: _host(v) for n, v in info[k].items()} if isinstance(info[k], dict) else _host(info[k]))
            for k in info}


@pytest.fixture(scope="module")
def device_env():
    """The device path's env, reset: the DLPack and argument checks need no script."""
    env = _make(True)
    env.reset(seed=3)
    yield env
    env.close()


@pytest.fixture(scope="module")
def rollout():
    """Both envs through the same actions; per step the numpy path's results and the device path's
    (copied to the host), the controls each wrote, and the device env for the later checks."""
    host, dev = _make(False), _make(True)
    oh, ih = host.reset(seed=7)
    od, idv = dev.reset(seed=7)
    acts = host.unwrapped.acts
    t_episode, episodes = np.zeros(W, dtype=int), np.zeros(W, dtype=int)
    steps = [((oh, None, None, None, ih), (_host(od), None, None, None, _host_info(idv)))]
    controls = []
    for _ in range(STEPS):
        a = _actions(t_episode, episodes)
        rh = host.step(a)
        rd = dev.step(a)
        steps.append((rh, (_host(rd[0]), _host(rd[1]), _host(rd[2]), _host(rd[3]), _host_info(rd[4]))))
        controls.append((host.unwrapped.sim.controls(acts), dev.unwrapped.sim.controls(acts)))
        ended = rh[2] | rh[3]
        episodes += ended
        t_episode = np.where(ended, 0, t_episode + 1)
    yield steps, controls, dev
    host.close()
    dev.close()


@pytest.mark.slow
def test_the_script_exercises_pulls_slips_drops_truncations_and_autoresets(rollout):
    steps, _, env = rollout
    c = env.unwrapped.config
    info = [s[0][4] for s in steps[1:]]
    obs = np.array([s[0][0] for s in steps[1:]])
    terminated = np.array([s[0][2] for s in steps[1:]])
    truncated = np.array([s[0][3] for s in steps[1:]])
    dropped = np.array([i["dropped"] for i in info])
    slip = np.array([i["slip_distance_m"] for i in info])
    assert np.array_equal(dropped, terminated) and dropped[:, 1].any() and dropped[:, 2].any()
    assert np.any(dropped & (slip > c.max_slip) & (obs[:, :, 8] > 0)), "a grasp lost by slip, jaws in contact"
    assert np.any(dropped[:, 2] & (obs[:, 2, 8] == 0)), "world 2 lost by opening its jaws: no contact left"
    assert truncated[:, 0].any() and not terminated[:, 0].any(), "world 0 holds until the time limit"
    success = np.array([i["success"] for i in info])
    assert success.any() and np.array_equal(success, truncated & (slip <= c.slip_tolerance))
    steps_taken = np.array([i["steps"] for i in info])
    assert (steps_taken == 0).sum() >= 4, "each episode end is followed by an autoreset"
    pull = np.array([i["pull_force_N"] for i in info])
    stepped = steps_taken > 0             # an autoreset world observes its new episode (no pull yet)
    assert pull.max() > 0.03 and np.all(obs[:, :, 9][stepped] == pull[stepped].astype(np.float32))
    assert np.all(obs[:, :, 9][~stepped] == 0.0)
    for name in info[0]["reward_terms"]:
        values = np.array([i["reward_terms"][name] for i in info])
        assert np.any(values != 0.0), f"reward term {name!r} never fired"


@pytest.mark.slow
def test_device_path_equals_the_numpy_path(rollout):
    steps, controls, _ = rollout
    (oh, *_, ih), (od, *_, idv) = steps[0]
    np.testing.assert_array_equal(od, oh, err_msg="reset observation")
    assert sorted(idv) == sorted(ih)
    for key in ih:
        np.testing.assert_array_equal(idv[key], ih[key], err_msg=f"reset info {key}")
    for k, ((oh, rh, teh, trh, ih), (od, rd, ted, trd, idv)) in enumerate(steps[1:], start=1):
        msg = f"control step {k}"
        assert od.dtype == np.float32 and rd.dtype == np.float64 and ted.dtype == bool
        np.testing.assert_array_equal(od, oh, err_msg=msg)
        np.testing.assert_array_equal(rd, rh, err_msg=msg)
        np.testing.assert_array_equal(ted, teh, err_msg=msg)
        np.testing.assert_array_equal(trd, trh, err_msg=msg)
        assert sorted(idv) == sorted(ih), msg
        assert list(idv["reward_terms"]) == list(ih["reward_terms"])
        for name, v in ih["reward_terms"].items():
            np.testing.assert_array_equal(idv["reward_terms"][name], v, err_msg=f"{name}, {msg}")
        for key in ih:
            if key != "reward_terms":
                np.testing.assert_array_equal(idv[key], ih[key], err_msg=f"{key}, {msg}")
        np.testing.assert_array_equal(controls[k - 1][1], controls[k - 1][0], err_msg=f"jaw and pull controls, {msg}")


def test_outputs_are_device_arrays_shared_through_dlpack(device_env):
    import warp as wp

    env = device_env
    obs, reward, terminated, truncated, info = env.step(np.zeros((W, 1), dtype=np.float32))
    for x in (obs, reward, terminated, truncated, info["reward_terms"]["hold"], info["slip_distance_m"],
              info["pull_force_N"], info["steps"]):
        assert isinstance(x, wp.array) and x.device == wp.get_device("cpu")
    shared = np.from_dlpack(obs)
    assert shared.shape == env.observation_space.shape and shared.dtype == np.float32
    assert shared.ctypes.data == obs.ptr, "np.from_dlpack must share the device array, not copy it"
    obs.fill_(7.0)                                   # a write into the Warp array shows in the numpy view
    assert np.all(shared == 7.0)
    later = env.step(np.zeros((W, 1), dtype=np.float32))[0]
    assert later.ptr != obs.ptr and np.all(shared == 7.0), "a new step writes new arrays: the kept ones stay"


def test_a_schedule_array_of_the_wrong_shape_is_refused(device_env):
    import warp as wp

    from surgsim_envs.errors import ConfigError

    env = device_env
    sim, acts = env.unwrapped.sim, env.unwrapped.acts
    bad = wp.zeros((2, W + 1, 2), dtype=wp.float64, device="cpu")
    with pytest.raises(ConfigError, match=rf"values must be a float64 Warp array of shape \(steps, {W}, 2\)"):
        sim.step_with_control_array(acts, bad)
    with pytest.raises(ConfigError, match=r"give numpy values to step_with_controls instead"):
        sim.step_with_control_array(acts, np.zeros((2, W, 2)))
