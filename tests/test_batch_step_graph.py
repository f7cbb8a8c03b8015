"""CUDA graphs of the batched physics (surgsim_envs/batch/step_graph.py), checked on Warp's CPU device.

Warp's CPU device cannot capture a graph, so these tests put a stand-in capture behind
:class:`StepGraphs` (it records the body and replays it by calling it) and check what a real capture
relies on:

* the recorded bodies (``BatchSimulation.step`` and a control schedule, in every batched task) do
  device work only: no device array is read on the host and the device is never synchronised
  inside them (either would break a capture, or silently record a stale value);
* a batch stepped through the graph path (one recording per kind of call, the schedule's values
  copied into the graph's own buffer) gives the same results, bit for bit, as plain launches, and
  its step counter still counts;
* the arrays a graph records keep their addresses through steps, resets and new materials;
* the modes: "on" where capture is impossible is a clear error; a failed capture warns, names the
  cause and falls back to plain launches without losing the step.

On a GPU ``graphs="auto"`` captures with ``wp.ScopedCapture``; ``test_cuda_graph_replays_the_same_steps``
runs there and skips elsewhere.
"""

import contextlib
import types

import numpy as np
import pytest

from surgsim_envs.batch.backend import available
from surgsim_envs.errors import ConfigError

pytestmark = pytest.mark.skipif(not available(), reason="needs the [batch] extra (warp-lang, mujoco-warp)")

W = 2


class HostAccess(AssertionError):
    pass


@contextlib.contextmanager
def device_work_only():
    """Raise HostAccess at any host read of a Warp array or device synchronisation."""
    import warp as wp

    def refuse(*args, **kwargs):
        raise HostAccess("host read or synchronisation inside a recorded body")

    saved = {name: getattr(wp, name) for name in ("synchronize", "synchronize_device", "synchronize_stream")}
    saved_numpy, saved_list = wp.array.numpy, wp.array.list
    try:
        for name in saved:
            setattr(wp, name, refuse)
        wp.array.numpy = refuse
        wp.array.list = refuse
        yield
    finally:
        for name, fn in saved.items():
            setattr(wp, name, fn)
        wp.array.numpy, wp.array.list = saved_numpy, saved_list


def stand_in_graphs(sim):
    """A StepGraphs on a device that claims capture, whose 'graph' is the recorded body itself,
    replayed under :func:`device_work_only`."""
    from surgsim_envs.batch.step_graph import StepGraphs

    fake_wp = types.SimpleNamespace(
        get_device=lambda d: types.SimpleNamespace(is_cuda=True, __str__=lambda self: "cuda:0"),
        is_mempool_enabled=lambda d: True, ScopedDevice=lambda d: contextlib.nullcontext(), capture_launch=None)
    replays = []

    def replay(body):
        replays.append(body)
        with device_work_only():
            body()

    sim.graphs = StepGraphs(fake_wp, "cuda:0", "auto", capture=lambda body: body, launch=replay)
    return replays


def _make(task, graphs="auto", device="cpu", **kw):
    """The task's batched env (its episode length from the config's episode_seconds)."""
    from gymnasium.envs.registration import load_env_creator

    from surgsim_envs.envs import BATCHED

    return load_env_creator(BATCHED[task])(W, device=device, graphs=graphs, **kw)


TASKS = {
    "SurgSim/Palpation-v0": dict(episode_seconds=0.2, min_report_seconds=0.05),
    "SurgSim/Grasp-v0": dict(control_hz=125.0, episode_seconds=0.08, closing_speed=0.06),
    "SurgSim/Slippage-v0": dict(control_hz=125.0, episode_seconds=0.08, closing_speed=0.5, settle_time=0.1,
                                pull_rate=(0.5, 1.0)),
}


def _rollout(env, steps, seed=0):
    rng = np.random.default_rng(seed)
    shape = (W,) + env.single_action_space.shape
    obs, _ = env.reset(seed=seed)
    out = [np.array(obs)]
    for _ in range(steps):
        obs, rew, term, trunc, _ = env.step(rng.uniform(-1, 1, shape))
        out += [np.array(obs), np.array(rew), np.array(term), np.array(trunc)]
    return out, env.sim.tissue_positions()


@pytest.mark.parametrize("task", [t if t == "SurgSim/Palpation-v0" else pytest.param(t, marks=pytest.mark.slow)
                                  for t in sorted(TASKS)])
def test_recorded_bodies_do_device_work_only_and_replay_bit_for_bit(task):
    """Each task through its graph path (episodes of a few steps: autoresets inside) against plain launches."""
    steps = 12
    plain = _make(task, graphs="off", **TASKS[task])
    ref, ref_x = _rollout(plain, steps)
    plain.close()
    env = _make(task, **TASKS[task])
    replays = stand_in_graphs(env.sim)
    got, x = _rollout(env, steps)
    assert env.sim.graphs.enabled and env.sim.graphs.failure == ""
    assert len(replays) == env.sim.graphs.replays >= steps            # every physics call went through a graph
    assert env.sim.graphs.captures == len(env.sim.graphs) < env.sim.graphs.replays   # recorded once per kind
    for a, b in zip(ref, got):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(ref_x, x)
    assert env.sim.steps == plain.sim.steps > 0
    env.close()


def test_a_schedule_replays_with_the_values_of_each_call():
    """Two calls of one schedule shape with different values: the second must not replay the first's."""
    from surgsim_envs.batch.simulation import BatchSimulation

    envs = []
    for graphs in ("off", "stand-in"):
        env = _make("SurgSim/Slippage-v0", graphs="off", **TASKS["SurgSim/Slippage-v0"])
        env.reset(seed=3)
        sim: BatchSimulation = env.sim
        if graphs == "stand-in":
            stand_in_graphs(sim)
        acts = env.acts
        for value in (0.002, -0.001):
            sim.step_with_controls(acts, np.full((3, W, len(acts)), value))
        envs.append(env)
    (a, b) = envs
    assert b.sim.graphs.captures == 1 and b.sim.graphs.replays == 2
    np.testing.assert_array_equal(a.sim.controls(a.acts), b.sim.controls(b.acts))
    np.testing.assert_array_equal(a.sim.tissue_positions(), b.sim.tissue_positions())
    assert a.sim.steps == b.sim.steps
    for env in envs:
        env.close()


def test_recorded_arrays_keep_their_addresses():
    """A graph records addresses: steps, resets, new materials and friction write in place."""
    env = _make("SurgSim/Palpation-v0", **TASKS["SurgSim/Palpation-v0"])
    sim = env.sim
    env.reset(seed=0)
    rng = np.random.default_rng(0)

    def addresses():
        arrays = dict(sim.arrays())
        for rec in (sim.tissue_state, sim.contact, sim.fields, sim.tools):
            arrays.update({f"{type(rec).__name__}.{k}": v for k, v in vars(rec).items() if hasattr(v, "ptr")})
        arrays.update({f"data.{k}": v for k, v in vars(sim.tools.data).items() if hasattr(v, "ptr")})
        return {k: v.ptr for k, v in arrays.items()}

    env.step(rng.uniform(-1, 1, (W,) + env.single_action_space.shape))
    before = addresses()
    assert len(before) > 40
    for _ in range(3):
        env.step(rng.uniform(-1, 1, (W,) + env.single_action_space.shape))
    env.reset(seed=1)
    sim.reset_worlds([1])
    sim.set_young_factors(np.full((1, sim.material_tets), 1.5), worlds=[0])
    sim.set_tool_friction([0.3], worlds=[1])
    assert addresses() == before
    env.close()


def test_modes_and_a_failed_capture():
    import warp as wp

    from surgsim_envs.batch.step_graph import StepGraphs

    with pytest.raises(ConfigError, match=r"graphs='on' on device cpu: Warp's CPU device cannot capture graphs; "
                                          r"use graphs='auto' or 'off'"):
        StepGraphs(wp, "cpu", "on")
    with pytest.raises(ConfigError, match=r"graphs='yes': use 'auto'"):
        StepGraphs(wp, "cpu", "yes")
    assert not StepGraphs(wp, "cpu", "auto").enabled             # plain launches on the CPU
    with pytest.raises(ConfigError, match=r"graphs='on' on device cpu"):
        _make("SurgSim/Palpation-v0", graphs="on")

    fake_wp = types.SimpleNamespace(get_device=lambda d: types.SimpleNamespace(is_cuda=True),
                                    is_mempool_enabled=lambda d: True, ScopedDevice=lambda d: contextlib.nullcontext(),
                                    capture_launch=None)

    def no_graphs(body):
        raise RuntimeError("graph capture is not supported by this driver")

    ran = []
    graphs = StepGraphs(fake_wp, "cuda:0", "auto", capture=no_graphs, launch=lambda g: ran.append("graph"))
    with pytest.warns(RuntimeWarning, match=r"capture of the batched physics failed .*RuntimeError: graph capture "
                                            r"is not supported by this driver.*plain kernel launches"):
        graphs.run(("step", 1), lambda: ran.append("body"))
    graphs.run(("step", 1), lambda: ran.append("body"))
    assert ran == ["body", "body"] and not graphs.enabled and "not supported" in graphs.failure

    off = StepGraphs(fake_wp, "cuda:0", "off", capture=no_graphs)
    off.run("k", lambda: ran.append("off"))
    assert ran[-1] == "off" and off.captures == 0


def test_cuda_graph_replays_the_same_steps():
    import warp as wp

    if not wp.get_cuda_device_count():
        pytest.skip("no CUDA device on this host (Warp sees none)")
    steps = 6
    ref, ref_x = _rollout(_make_cuda("off"), steps)
    env = _make_cuda("auto")
    got, x = _rollout(env, steps)
    assert env.sim.graphs.enabled and env.sim.graphs.replays >= steps
    for a, b in zip(ref, got):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(ref_x, x)


def _make_cuda(graphs):
    return _make("SurgSim/Palpation-v0", graphs=graphs, device="cuda", **TASKS["SurgSim/Palpation-v0"])


def test_profiling_and_make_vec_pass_through():
    """Profiling runs plain launches (its phases synchronise); gym.make_vec passes ``graphs`` on."""
    import gymnasium as gym

    env = gym.make_vec("SurgSim/Palpation-v0", num_envs=W, vectorization_mode="vector_entry_point", device="cpu",
                       graphs="off", max_episode_steps=20, **TASKS["SurgSim/Palpation-v0"])
    assert env.sim.graphs.mode == "off" and not env.sim.graphs.enabled
    env.reset(seed=0)
    replays = stand_in_graphs(env.sim)
    env.sim.step(env.substeps)
    assert len(replays) == 1
    env.sim.profile(True)
    env.sim.step(env.substeps)
    env.sim.profile(False)
    assert len(replays) == 1 and env.sim.phase_seconds is None
    env.close()
