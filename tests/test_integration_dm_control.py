"""Every SurgSim task loads and steps as a dm_control environment."""

import numpy as np
import pytest

pytest.importorskip("dm_control", reason="dm-control is a dependency of surgsim_envs (pip install dm-control)")

from surgsim_envs.integrations import dm_control as surgsim_dm_control  # noqa: E402
from surgsim_envs.errors import ConfigError  # noqa: E402

FAST = {"palpation": {"spacing": 0.02, "episode_seconds": 0.05, "min_report_seconds": 0.0,
                      "max_episode_steps": 5},
        "grasp": {"resolution": 0.015, "episode_seconds": 0.1, "max_episode_steps": 5},
        "slippage": {"resolution": 0.015, "episode_seconds": 0.1, "max_episode_steps": 5},
        "palpationpress": {"spacing": 0.02, "max_presses": 3, "max_episode_steps": 3},
        "layeredpalpation": {"spacing": 0.01, "max_presses": 3, "max_episode_steps": 3}}


@pytest.mark.parametrize("name", surgsim_dm_control.names())
def test_load_steps_every_task_to_its_time_limit(name):
    from dm_control.rl import control

    kw = {k: v for k, v in FAST[name].items() if k != "max_episode_steps"}
    env = surgsim_dm_control.load(name, task_kwargs={**kw, "random": 3})
    assert isinstance(env, control.Environment)
    u = env.physics.env
    assert env.physics.timestep() == pytest.approx(1.0 / u.config.control_hz)
    ts = env.reset()
    assert ts.first() and list(ts.observation) == [t.name for t in u.observation_terms]
    spec = env.action_spec()
    steps = 0
    while True:
        ts = env.step(np.zeros(spec.shape, dtype=np.float32))
        steps += 1
        assert all(np.all(np.isfinite(v)) for v in ts.observation.values())
        assert ts.reward == pytest.approx(sum(env.physics.last_info["reward_terms"].values()))
        # the dm_control data follows the task's simulation (render twin)
        np.testing.assert_allclose(env.physics.data.qpos, u.sim.data.qpos)
        if ts.last():
            break
        assert steps < 20
    assert steps == u.max_episode_steps or ts.discount == 0.0


def test_unknown_name_and_render():
    with pytest.raises(ConfigError, match="unknown SurgSim task 'suturing'"):
        surgsim_dm_control.load("suturing")
    env = surgsim_dm_control.load("palpation", task_kwargs={"spacing": 0.02})
    env.reset()
    try:
        frame = env.physics.render(96, 128, camera_id="overview")
    except Exception as exc:  # no OpenGL here
        pytest.skip(f"no OpenGL for rendering: {exc}")
    assert frame.shape == (96, 128, 3) and frame.std() > 5       # a scene, not a blank image


def test_layered_palpation_loads_by_its_snake_case_name():
    """``load("layered_palpation")`` is LayeredPalpation-v0; its dm_control clock runs one nominal
    press period per step and the scene's wall mirrors the task's pressed wall."""
    env = surgsim_dm_control.load("layered_palpation", task_kwargs={"spacing": 0.01, "max_presses": 2, "random": 1})
    u = env.physics.env
    assert type(u).__name__ == "LayeredPalpationEnv"
    env.reset()
    ts = env.step(np.array([0.0, 0.0, 1.0, -1.0], dtype=np.float32))   # over a node of the 1 cm lattice
    assert ts.observation["probe_force"][0] > 0
    assert env.physics.time() == pytest.approx(u.control_dt)
    np.testing.assert_allclose(u.sim.tissue("wall").positions, u.tissue.positions)
