"""The per-step fast paths keep the env's contract (actions checked and
clipped without touching the caller's array, fresh observation and info objects every step), the
InfoKeys wrapper, and Grasp-v0's sub-cycling default with the grasper stability limit behind it."""

from __future__ import annotations

import copy
import functools

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import surgsim_envs  # noqa: F401
from surgsim_envs.envs.grasp import GraspConfig
from surgsim_envs.envs.grasp import MAX_SUBCYCLED_RIGID_DT, resolved_subcycles
from surgsim_envs.envs.slippage import SlippageConfig
from surgsim_envs.envs.wrappers import InfoKeys
from surgsim_envs.errors import ConfigError


def test_action_fast_path_clips_a_copy_and_still_refuses_nan(palpation):
    u = palpation.unwrapped
    palpation.reset(seed=0)
    raw = np.array([2.0, -3.0, 0.25, -1.0], dtype=np.float32)
    a = u.check_action(raw)
    assert a.dtype == np.float64 and a.tolist() == [1.0, -1.0, 0.25, -1.0]
    assert raw.tolist() == [2.0, -3.0, 0.25, -1.0]             # the caller's array is untouched
    with pytest.raises(ConfigError, match="NaN or inf"):
        u.check_action(np.array([np.nan, 0, 0, 0], dtype=np.float32))
    with pytest.raises(ConfigError, match="shape"):
        u.check_action(np.zeros(3, dtype=np.float32))


def test_every_step_returns_fresh_observation_and_info_objects(palpation):
    palpation.reset(seed=1)
    a = np.array([0.0, 0.0, 0.8, -1.0], dtype=np.float32)      # press: the stiffness map fills in
    kept = [palpation.step(a) for _ in range(40)]
    obs = [k[0] for k in kept]
    infos = [k[4] for k in kept]
    assert len({id(o) for o in obs}) == len(obs)
    assert len({id(i) for i in infos}) == len(infos)
    assert len({id(i["reward_terms"]) for i in infos}) == len(infos)
    assert len({id(i["inclusion_centre_m"]) for i in infos}) == len(infos)
    before = obs[-1].copy()
    obs[-2][:] = 123.0                                          # a user scribbling on an old observation
    infos[-2]["reward_terms"]["time"] = 99.0
    assert np.array_equal(obs[-1], before)
    nxt = palpation.step(a)
    assert np.all(nxt[0] != 123.0) and nxt[4]["reward_terms"]["time"] != 99.0
    assert np.any(obs[-1][14:] > 0)                             # the (cached) map entries are in the observation


def test_info_keys_wrapper_keeps_only_named_entries():
    env = InfoKeys(gym.make("SurgSim/Grasp-v0"), keys=("is_success", "grasped"))
    _, info = env.reset(seed=0)
    assert set(info) == {"is_success"}                          # "grasped" exists only after a step
    info = env.step(env.action_space.sample())[4]
    assert set(info) == {"is_success", "grasped"}
    env.close()
    with pytest.raises(ConfigError, match="sequence of info key names"):
        InfoKeys(gym.make("SurgSim/Grasp-v0"), keys="is_success")
    vec = gym.make_vec("SurgSim/Grasp-v0", num_envs=2, vectorization_mode="sync",
                       wrappers=[functools.partial(InfoKeys, keys=("is_success",))])
    vec.reset(seed=0)
    infos = vec.step(vec.action_space.sample())[4]
    assert set(infos) == {"is_success", "_is_success"}
    vec.close()


def test_grasp_subcycles_auto_resolution():
    assert resolved_subcycles(GraspConfig()) == 2                          # 50 x 0.4 ms: MuJoCo at 0.8 ms
    assert resolved_subcycles(SlippageConfig()) == 1                       # its shipped policy was trained at 1
    assert resolved_subcycles(GraspConfig(control_hz=1 / (0.4e-3 * 49))) == 1  # odd substeps
    assert resolved_subcycles(GraspConfig(dt=5e-4)) == 1                   # 2 dt = 1 ms > the grasper's limit
    assert resolved_subcycles(GraspConfig(tissue_subcycles=1)) == 1
    GraspConfig(tissue_subcycles="auto", control_hz=1 / (0.4e-3 * 49)).validate()
    with pytest.raises(ConfigError, match="or 'auto'"):
        GraspConfig(tissue_subcycles="fast").validate()
    env = gym.make("SurgSim/Grasp-v0")
    assert env.unwrapped.sim.tissue_subcycles == 2
    assert env.unwrapped.sim.model.opt.timestep == pytest.approx(8e-4)
    env.close()


def _jaw_runs_away(m, jaw_actuator: int, dt: float) -> bool:
    """Close the jaws of the grasper (no tissue) for 0.3 s with MuJoCo steps of ``dt``."""
    m.opt.timestep = dt
    d = mujoco.MjData(m)
    d.ctrl[jaw_actuator] = 0.004        # 4 mm of closing travel
    for _ in range(int(round(0.3 / dt))):
        mujoco.mj_step(m, d)
        if not np.all(np.isfinite(d.qacc)) or np.abs(d.qvel).max() > 100.0:
            return True
    return False


def test_grasper_alone_limits_the_subcycled_mujoco_step():
    """Why tissue_subcycles=5 (a 2 ms MuJoCo step) blew up and "auto" stops at 0.8 ms: the jaw
    servo (kp 20 kN/m on 20 g jaws, omega ~ 1,000 rad/s) is explicit in the position gain, so the
    grasper diverges on its own from 1.6 ms, with no tissue at all."""
    env = gym.make("SurgSim/Grasp-v0")
    sim = env.unwrapped.sim
    m = copy.deepcopy(sim.model)            # the physics model of the task; the env's own is untouched
    jaw = int(sim.tool("grasper").jaw_actuator_id)
    assert not _jaw_runs_away(m, jaw, MAX_SUBCYCLED_RIGID_DT)
    assert _jaw_runs_away(m, jaw, 2 * MAX_SUBCYCLED_RIGID_DT)
    assert sim.model.opt.timestep == pytest.approx(MAX_SUBCYCLED_RIGID_DT)
    env.close()
