"""Grasp-v0's device path (``device_outputs=True``: batch/grasp_kernels.py) against its numpy path
(the default), 3 worlds on Warp's CPU device.

Both envs step the same physics (the same kernels, bit for bit), so what is compared is the task
bookkeeping. Over 200 control steps of a fixed script (seed 11; 0.48 s episodes at 125 Hz, 60
control steps, so each control step is 20 physics steps and the file stays short): world 0 closes
the jaws and pulls the grasped organ to its target (success, several episodes); world 1 closes,
holds, then opens the jaws (the grasp is lost: drop); world 2 closes and holds until the time limit
(truncation); every episode end is followed by a NEXT_STEP autoreset. Every observation, reward,
reward term, terminated/truncated flag and info entry of the device path equals the numpy path's
exactly: the kernels do the host's arithmetic in the host's order (the jaws' forces summed in
order, BLAS's in-order dot for the norms, the slip tracker's centroid added in node order then
divided by the count, Python's ``sum`` of the terms), compiled without floating-point contraction,
and no operation in the chain goes through a numpy SIMD kernel whose result depends on the CPU's
features (checked with ``NPY_DISABLE_CPU_FEATURES`` set: equal too).

The scripted run takes about a minute on Warp's CPU device, so it runs under ``-m slow``; the default
run keeps the checks that need no script (DLPack sharing, argument errors). Palpation-v0's device path
(tests/test_batch_device_terms.py) is the default run's representative of the comparison.
"""

import numpy as np
import pytest

from surgsim_envs.batch.backend import available

pytestmark = pytest.mark.skipif(not available(), reason="needs the [batch] extra (warp-lang, mujoco-warp)")

W = 3
STEPS = 200
HZ, EPISODE = 125.0, 0.48
#: 60-step episodes at 125 Hz (20 physics steps a control step), jaws at 0.06 m/s (grasp at control
#: step 25), a target 6-8 mm out, a damage threshold the grip passes (the excess-force term fires)
TASK = dict(control_hz=HZ, episode_seconds=EPISODE, closing_speed=0.06, damage_force=0.1,
            target_offset_x=(0.006, 0.008), target_offset_z=(0.0, 0.002))
CLOSE = 25          # control steps of closing before world 0 pulls
OPEN_AT = CLOSE + 8  # world 1 opens its jaws here


def _make(device_outputs):
    import gymnasium as gym

    return gym.make_vec("SurgSim/Grasp-v0", num_envs=W, vectorization_mode="vector_entry_point", device="cpu",
                        max_episode_steps=int(round(EPISODE * HZ)), device_outputs=device_outputs, **TASK)


def _actions(t_episode, obs):
    """World 0: close, then move the wrist towards the target at 0.6 of the step; world 1: close,
    hold, open at ``OPEN_AT``; world 2: close and hold."""
    a = np.zeros((W, 4))
    a[:, 3] = 1.0
    if t_episode[0] >= CLOSE:
        a[0, :3] = np.clip(obs[0, 3:6] / 0.001 * 0.6, -0.6, 0.6)
    if t_episode[1] >= OPEN_AT:
        a[1, 3] = -1.0
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
    (copied to the host), and the device env for the later checks."""
    host, dev = _make(False), _make(True)
    oh, ih = host.reset(seed=11)
    od, idv = dev.reset(seed=11)
    t_episode = np.zeros(W, dtype=int)
    steps = [((oh, None, None, None, ih), (_host(od), None, None, None, _host_info(idv)))]
    for _ in range(STEPS):
        a = _actions(t_episode, oh)
        rh = host.step(a)
        rd = dev.step(a)
        steps.append((rh, (_host(rd[0]), _host(rd[1]), _host(rd[2]), _host(rd[3]), _host_info(rd[4]))))
        oh = rh[0]
        t_episode = np.where(rh[2] | rh[3], 0, t_episode + 1)
    yield steps, dev
    host.close()
    dev.close()


@pytest.mark.slow
def test_the_script_exercises_grasps_successes_drops_truncations_and_terms(rollout):
    steps, _ = rollout
    info = [s[0][4] for s in steps[1:]]
    success = np.array([i["success"] for i in info])
    dropped = np.array([i["dropped"] for i in info])
    trunc = np.array([s[0][3] for s in steps[1:]])
    assert success[:, 0].sum() >= 3 and not success[:, 1:].any(), "world 0 reaches its target, again and again"
    assert dropped[:, 1].sum() >= 3 and not dropped[:, [0, 2]].any(), "world 1 loses its grasp when it opens"
    assert trunc[:, 2].sum() >= 2 and not trunc[:, :2].any(), "world 2 holds until the time limit"
    steps_taken = np.array([i["steps"] for i in info])
    assert (steps_taken == 0).sum() >= 8, "each episode end is followed by an autoreset"
    slip = np.array([i["slip_distance_m"] for i in info])
    assert slip.max() > 1e-4, "the slip tracker follows the grasped nodes"
    for name in info[0]["reward_terms"]:
        values = np.array([i["reward_terms"][name] for i in info])
        assert np.any(values != 0.0), f"reward term {name!r} never fired"


@pytest.mark.slow
def test_device_path_equals_the_numpy_path(rollout):
    steps, _ = rollout
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
            if key != "reward_terms":            # distance_to_target_m is NaN before a world's first step
                np.testing.assert_array_equal(idv[key], ih[key], err_msg=f"{key}, {msg}")


def test_outputs_are_device_arrays_shared_through_dlpack(device_env):
    import warp as wp

    env = device_env
    obs, reward, terminated, truncated, info = env.step(np.zeros((W, 4), dtype=np.float32))
    for x in (obs, reward, terminated, truncated, info["reward_terms"]["contact"], info["slip_distance_m"],
              info["grasped"], info["steps"]):
        assert isinstance(x, wp.array) and x.device == wp.get_device("cpu")
    shared = np.from_dlpack(obs)
    assert shared.shape == env.observation_space.shape and shared.dtype == np.float32
    assert shared.ctypes.data == obs.ptr, "np.from_dlpack must share the device array, not copy it"
    assert not np.all(shared == 7.0)
    obs.fill_(7.0)                                   # a write into the Warp array shows in the numpy view
    assert np.all(shared == 7.0)
    later = env.step(np.zeros((W, 4), dtype=np.float32))[0]
    assert later.ptr != obs.ptr and np.all(shared == 7.0), "a new step writes new arrays: the kept ones stay"


def test_python_sum_reproduced_plain_and_compensated():
    """The kernels' ``sum()`` of the reward terms: the plain order (Python <= 3.11) and Neumaier's
    compensation (3.12+), both bit for bit against a reference of each on values where they differ."""
    import warp as wp

    from surgsim_envs.batch import device_reductions as R

    @wp.kernel
    def sums(v: wp.array2d(dtype=wp.float64), compensated: int, out: wp.array(dtype=wp.float64)):
        w = wp.tid()
        acc = wp.vec2d(wp.float64(0.0), wp.float64(0.0))
        for i in range(v.shape[1]):
            acc = R.python_sum_add(acc, v[w, i], compensated)
        out[w] = R.python_sum_total(acc)

    def neumaier(values):
        f, c = 0.0, 0.0
        for x in values:
            t = f + x
            c += (f - t) + x if abs(f) >= abs(x) else (x - t) + f
            f = t
        return f + c if c and np.isfinite(c) else f

    def plain(values):
        total = 0
        for x in values:
            total = total + x
        return float(total)

    rng = np.random.default_rng(3)
    v = rng.normal(0.0, 1.0, (64, 6)) * 10.0 ** rng.integers(-8, 3, (64, 6))
    v[0] = [1e16, 1.0, -1e16, 0.0, 0.0, 0.0]         # compensation matters
    out = wp.zeros(len(v), dtype=wp.float64, device="cpu")
    for compensated, reference in ((0, plain), (1, neumaier)):
        wp.launch(sums, dim=len(v), inputs=[wp.array(v, dtype=wp.float64, device="cpu"), compensated], outputs=[out],
                  device="cpu")
        np.testing.assert_array_equal(out.numpy(), [reference(row.tolist()) for row in v])
    assert plain(v[0].tolist()) != neumaier(v[0].tolist())
    expected = neumaier if R.PYTHON_SUM_COMPENSATED else plain
    np.testing.assert_array_equal([sum(row.tolist()) for row in v], [expected(row.tolist()) for row in v])
