"""Palpation-v0's device path (``device_outputs=True``: batch/palpation_kernels.py) against its
numpy path (the default), 4 worlds on Warp's CPU device.

Both envs step the same physics (the same kernels, bit for bit), so what is compared is the task
bookkeeping: over 220 control steps of a fixed script plus random actions (presses still enough to
take stiffness samples, a deep press past the lowered damage threshold, held reports that end
episodes, a world that never reports and is truncated twice, NEXT_STEP autoresets), every
observation, reward, reward term, terminated/truncated flag and info readout of the device path
equals the numpy path's exactly, with one exception and its bound: numpy computes ``x ** 3.0`` of
the stiffness weights with its own SIMD ``pow`` on AVX-512 hosts (up to 1 ulp from the C library's
``pow`` the kernel calls), so the running estimate may differ in its last bits. Carried through:
the estimate's observation entries within 1 float32 ulp, the potential, shaping and localisation
terms, the reward and the guess's error within 1e-14 (each weight is <= 1, the estimate a
weighted mean of positions <= 0.05 m, so a few float64 ulps of it move phi by ~1e-16).

The default run compares the first 40 control steps (presses, samples, a held report that ends an
episode: about 10 s); the whole script runs under ``-m slow`` (about a minute on Warp's CPU device).
"""

import numpy as np
import pytest

from surgsim_envs.batch.backend import available

pytestmark = pytest.mark.skipif(not available(), reason="needs the [batch] extra (warp-lang, mujoco-warp)")

W = 4
STEPS = 220
#: the default run's share of the script: the first presses, samples and a held report (the whole
#: script, with both truncations and every reward term firing, runs under ``-m slow``)
SHORT_STEPS = 40
#: 1 s episodes (100 control steps: truncation inside the run), reports from 0.2 s, a damage
#: threshold the deep presses pass (the default tissue pushes back 0.2-0.45 N)
TASK = dict(episode_seconds=1.0, min_report_seconds=0.2, damage_force=0.2)
#: the estimate's float64 last bits carried through the potential and the rewards (module docstring)
ESTIMATE_BOUND = 1e-14


def _make(device_outputs):
    import gymnasium as gym

    return gym.make_vec("SurgSim/Palpation-v0", num_envs=W, vectorization_mode="vector_entry_point", device="cpu",
                        max_episode_steps=100, device_outputs=device_outputs, **TASK)


def _press_cycle(t, period, report_from, deep=False):
    """Move for 3 steps, press still for 8 (quasi-static samples), lift; hold report from ``report_from``."""
    phase = t % period
    if phase < 3:
        a = [0.8, -0.5 if (t // period) % 2 else 0.5, -1.0, -1.0]
    elif phase < 11:
        a = [0.0, 0.0, 1.0 if deep else 0.6, -1.0]
    else:
        a = [0.0, 0.0, -1.0, -1.0]
    if t >= report_from:
        a[3] = 1.0
    return a


def _actions(t_episode, rng):
    a = np.zeros((W, 4))
    a[0] = _press_cycle(t_episode[0], 13, 40)
    r = rng.uniform(-1, 1, 4)                    # random, never reports: truncated at 100 steps
    r[3] = -1.0
    a[1] = r
    a[2] = _press_cycle(t_episode[2], 12, 27, deep=True)
    a[3] = _press_cycle(t_episode[3], 14, 70)
    if t_episode[3] % 31 == 30:                  # a one-step report flick: not held, no termination
        a[3, 3] = 1.0
    return a.astype(np.float32)


def _host(x):
    return x.numpy().copy() if hasattr(x, "numpy") and not isinstance(x, np.ndarray) else np.array(x)


def _rollout(n_steps):
    """Both envs through the same actions; per step the numpy path's results and the device path's
    (copied to the host), and the device env for the later checks."""
    host, dev = _make(False), _make(True)
    oh, _ = host.reset(seed=5)
    od, _ = dev.reset(seed=5)
    rng = np.random.default_rng(0)
    t_episode = np.zeros(W, dtype=int)
    steps = [((oh, None, None, None, None), (_host(od), None, None, None, None))]
    for _ in range(n_steps):
        a = _actions(t_episode, rng)
        rh = host.step(a)
        rd = dev.step(a)
        info = rd[4]
        dinfo = {k: ({n: _host(v) for n, v in info[k].items()} if isinstance(info[k], dict) else _host(info[k]))
                 for k in info}
        steps.append((rh, (_host(rd[0]), _host(rd[1]), _host(rd[2]), _host(rd[3]), dinfo)))
        t_episode = np.where(rh[2] | rh[3], 0, t_episode + 1)
    return steps, host, dev


@pytest.fixture(scope="module")
def rollout():
    steps, host, dev = _rollout(STEPS)
    yield steps, dev
    host.close()
    dev.close()


@pytest.fixture(scope="module")
def short_rollout():
    steps, host, dev = _rollout(SHORT_STEPS)
    yield steps, dev
    host.close()
    dev.close()


@pytest.mark.slow
def test_the_script_exercises_samples_terms_reports_and_truncation(rollout):
    steps, _ = rollout
    term = np.array([s[0][2] for s in steps[1:]])
    trunc = np.array([s[0][3] for s in steps[1:]])
    assert term[:, 0].sum() >= 2 and term[:, 2].sum() >= 3 and term[:, 3].sum() >= 1, "held reports end episodes"
    assert trunc[:, 1].sum() == 2 and not term[:, 1].any(), "the random world runs into the time limit twice"
    for name in steps[1][0][4]["reward_terms"]:
        values = np.array([s[0][4]["reward_terms"][name] for s in steps[1:]])
        assert np.any(values != 0.0), f"reward term {name!r} never fired"
    contrast = np.array([s[0][0][:, 13] for s in steps[1:]])
    assert (contrast > 1.0).mean() > 0.5, "the presses take stiffness samples (contrast seen > 1)"


def test_the_first_steps_take_samples_and_end_an_episode_by_a_held_report(short_rollout):
    steps, _ = short_rollout
    term = np.array([s[0][2] for s in steps[1:]])
    assert term[:, 2].sum() >= 1, "world 2's held report ends its episode"
    contrast = np.array([s[0][0][:, 13] for s in steps[1:]])
    assert (contrast > 1.0).any(), "the presses take stiffness samples (contrast seen > 1)"


def test_device_path_equals_the_numpy_path_over_the_first_steps(short_rollout):
    _assert_paths_equal(short_rollout[0])


@pytest.mark.slow
def test_device_path_equals_the_numpy_path(rollout):
    _assert_paths_equal(rollout[0])


def _assert_paths_equal(steps):
    (oh, *_), (od, *_) = steps[0]
    np.testing.assert_array_equal(od, oh, err_msg="reset observation")
    exact = [i for i in range(oh.shape[1]) if i not in (11, 12)]
    for k, ((oh, rh, teh, trh, ih), (od, rd, ted, trd, idv)) in enumerate(steps[1:], start=1):
        msg = f"control step {k}"
        assert od.dtype == np.float32 and rd.dtype == np.float64
        np.testing.assert_array_equal(od[:, exact], oh[:, exact], err_msg=msg)
        np.testing.assert_array_max_ulp(od[:, 11:13], oh[:, 11:13], maxulp=1)
        np.testing.assert_array_equal(ted, teh, err_msg=msg)
        np.testing.assert_array_equal(trd, trh, err_msg=msg)
        np.testing.assert_allclose(rd, rh, rtol=0, atol=ESTIMATE_BOUND, err_msg=msg)
        assert list(idv["reward_terms"]) == list(ih["reward_terms"])
        for name, v in ih["reward_terms"].items():
            if name in ("shaping", "localisation"):      # built on the estimate
                np.testing.assert_allclose(idv["reward_terms"][name], v, rtol=0, atol=ESTIMATE_BOUND, err_msg=name)
            else:
                np.testing.assert_array_equal(idv["reward_terms"][name], v, err_msg=f"{name}, {msg}")
        for key in ("force_N", "stiffness_estimate_N_per_m", "peak_force_N", "steps"):
            np.testing.assert_array_equal(idv[key], ih[key], err_msg=f"{key}, {msg}")
        np.testing.assert_allclose(idv["final_reward"], ih["final_reward"], rtol=0, atol=ESTIMATE_BOUND)
        ended = teh | trh
        np.testing.assert_array_equal(idv["_success"], ended, err_msg=msg)
        if ended.any():
            np.testing.assert_array_equal(idv["success"], ih["success"], err_msg=msg)
            np.testing.assert_allclose(idv["localisation_error_m"][ended], ih["localisation_error_m"][ended],
                                       rtol=0, atol=ESTIMATE_BOUND, err_msg=msg)


def test_outputs_are_device_arrays_shared_through_dlpack(short_rollout):
    import warp as wp

    _, env = short_rollout
    obs, reward, terminated, truncated, info = env.step(np.zeros((W, 4), dtype=np.float32))
    for x in (obs, reward, terminated, truncated, info["force_N"], info["reward_terms"]["time"]):
        assert isinstance(x, wp.array) and x.device == wp.get_device("cpu")
    shared = np.from_dlpack(obs)
    assert shared.shape == env.observation_space.shape and shared.dtype == np.float32
    assert shared.ctypes.data == obs.ptr, "np.from_dlpack must share the device array, not copy it"
    assert not np.all(shared == 7.0)
    obs.fill_(7.0)                                   # a write into the Warp array shows in the numpy view
    assert np.all(shared == 7.0)
    terms = np.from_dlpack(info["reward_terms"]["time"])
    assert terms.ctypes.data == info["reward_terms"]["time"].ptr
    np.testing.assert_array_equal(terms, -env.config.time_cost)
    np.testing.assert_array_equal(np.from_dlpack(terminated), terminated.numpy())
    later = env.step(np.zeros((W, 4), dtype=np.float32))[0]
    assert later.ptr != obs.ptr and np.all(shared == 7.0), "a new step writes new arrays: the kept ones stay"


def test_device_outputs_refused_where_not_computed_on_the_device():
    """Every batched task computes its outputs on the device; a task env without ``DEVICE_OUTPUTS``
    (a host-only subclass here) is refused before anything is built, and so is a non-bool value."""
    import gymnasium as gym

    from gymnasium.envs.registration import load_env_creator

    from surgsim_envs.batch.slippage_env import BatchedSlippageEnv
    from surgsim_envs.envs.registry import TASKS
    from surgsim_envs.errors import ConfigError

    batched = [spec.batched for spec in TASKS.values() if spec.batched is not None]
    assert len(batched) == 3
    for spec in TASKS.values():
        if spec.batched is not None:
            assert load_env_creator(spec.batched).DEVICE_OUTPUTS, spec.batched

    class HostOnlySlippage(BatchedSlippageEnv):
        DEVICE_OUTPUTS = False

    with pytest.raises(ConfigError, match=r"device_outputs=True: HostOnlySlippage computes its observations and "
                                          r"rewards on the host \(numpy\); only BatchedPalpationEnv "
                                          r"\(SurgSim/Palpation-v0\), BatchedGraspEnv \(SurgSim/Grasp-v0\) and "
                                          r"BatchedSlippageEnv \(SurgSim/Slippage-v0\) compute them on the device\. "
                                          r"Leave device_outputs out"):
        HostOnlySlippage(2, device="cpu", device_outputs=True)
    for task in ("SurgSim/Palpation-v0", "SurgSim/Slippage-v0"):
        with pytest.raises(ConfigError, match=r"device_outputs='yes' must be True .* or False"):
            gym.make_vec(task, num_envs=2, vectorization_mode="vector_entry_point", device="cpu",
                         device_outputs="yes")


def test_kernel_arithmetic_is_numpys_bit_for_bit():
    """The kernels' pairwise sum (beyond one 128-block: the splitting the short episodes above do
    not reach), sorted-buffer median (odd and even counts, ties) and hypot equal numpy's exactly."""
    import warp as wp

    from surgsim_envs.batch import palpation_kernels as K

    @wp.kernel
    def arithmetic(a: wp.array2d(dtype=wp.float64), n: wp.array(dtype=wp.int32), buf: wp.array2d(dtype=wp.float64),
                   xy: wp.array2d(dtype=wp.float64), sums: wp.array(dtype=wp.float64),
                   medians: wp.array(dtype=wp.float64), hyp: wp.array(dtype=wp.float64)):
        w = wp.tid()
        count = n[w]
        sums[w] = K.pairwise_sum(a, w, count)
        for i in range(count):
            K.insert_sorted(buf, w, i, a[w, i])
        medians[w] = K.sorted_median(buf, w, count)
        hyp[w] = K.glibc_hypot(xy[w, 0], xy[w, 1])

    rng = np.random.default_rng(7)
    counts = np.concatenate([np.arange(1, 20), [127, 128, 129, 255, 256, 257, 300, 463, 600, 911, 1000]])
    cap = int(counts.max())
    a = rng.lognormal(3.0, 1.0, (len(counts), cap)) ** 3
    a[5, :4] = a[5, 4]                               # ties
    xy = rng.normal(0.0, 0.02, (len(counts), 2))
    xy[0, 1] = 0.0                                   # an axis-aligned pair
    xy[1] = (1e-300, 3e-300)                         # glibc's scaled branches
    xy[2] = (1e200, 2e200)
    dev = "cpu"
    out = [wp.zeros(len(counts), dtype=wp.float64, device=dev) for _ in range(3)]
    wp.launch(arithmetic, dim=len(counts), device=dev,
              inputs=[wp.array(a, dtype=wp.float64, device=dev), wp.array(counts.astype(np.int32), device=dev),
                      wp.zeros((len(counts), cap), dtype=wp.float64, device=dev),
                      wp.array(xy, dtype=wp.float64, device=dev)], outputs=out)
    sums, medians, hyp = (x.numpy() for x in out)
    np.testing.assert_array_equal(sums, [a[i, :c].sum() for i, c in enumerate(counts)])
    np.testing.assert_array_equal(medians, [np.median(a[i, :c]) for i, c in enumerate(counts)])
    np.testing.assert_array_equal(hyp, np.hypot(xy[:, 0], xy[:, 1]))
    assert K.pairwise_capacity() >= 600, "the default 6 s episode's 600 samples fit the unrolled pairwise sum"
