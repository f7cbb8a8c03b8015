"""``SceneConfig.rigid_contacts``: a scene whose tools cannot touch a rigid geom runs without MuJoCo's
collision detection (Palpation-v0 when the slab is thicker than the probe's reach); the physics is the
same bit for bit, and a slab the probe could press through keeps the floor solid."""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np

import surgsim_envs  # noqa: F401  (registers the tasks)

FLAG = int(mujoco.mjtDisableBit.mjDSBL_CONTACT)


def _flag(env) -> int:
    return int(env.unwrapped.sim.model.opt.disableflags) & FLAG


def test_palpation_without_collision_detection_steps_the_same():
    off = gym.make("SurgSim/Palpation-v0")
    on = gym.make("SurgSim/Palpation-v0")
    try:
        off.reset(seed=5)
        on.reset(seed=5)
        assert _flag(off) == FLAG
        on.unwrapped.sim.model.opt.disableflags &= ~FLAG         # the same scene with MuJoCo's collisions on
        acts = np.random.default_rng(2).uniform(-1, 1, (120, 4)).astype(np.float32)
        acts[:, 2] = np.linspace(-1, 1, 120)                     # press down to the deepest target
        acts[:, 3] = -1.0
        for a in acts:
            r1, r2 = off.step(a), on.step(a)
            assert np.array_equal(r1[0], r2[0]) and r1[1] == r2[1]
        assert on.unwrapped.sim.data.ncon == 0                   # nothing rigid was touched
    finally:
        off.close()
        on.close()


def test_thin_slab_keeps_the_floor_solid():
    """A 12 mm slab with the 8 mm press depth leaves 4 mm to the floor (< RIGID_CONTACT_CLEARANCE): the
    collision detection stays on."""
    env = gym.make("SurgSim/Palpation-v0", slab_size=(0.1, 0.1, 0.012))
    try:
        env.reset(seed=0)
        assert _flag(env) == 0
    finally:
        env.close()


def test_rigid_contacts_must_be_a_bool():
    """A string such as "no" would be truthy and silently keep collisions on: refused by name."""
    import pytest

    from surgsim_envs.errors import ConfigError
    from surgsim_envs.scene.builder import palpation_config
    from surgsim_envs.scene.config_check import validate_scene_config

    cfg = palpation_config()
    cfg.rigid_contacts = "no"
    with pytest.raises(ConfigError, match=r"scene 'palpation' rigid_contacts must be True or False, got 'no'"):
        validate_scene_config(cfg)
