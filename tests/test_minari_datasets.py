"""Demonstrations recorded as Minari datasets (`surgsim record`): what they hold, that a recording
replays exactly from its seeds, and the refusals."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("minari", reason="Minari is in the [test] and [data] extras")

from surgsim_envs.errors import ConfigError  # noqa: E402
from surgsim_envs.integrations import minari_datasets as md  # noqa: E402


def test_an_expert_recording_holds_forces_in_newtons_and_replays_from_its_seeds(tmp_path):
    import gymnasium as gym

    ds = md.record("SurgSim/Grasp-v0", "expert", episodes=2, seed=7, out=tmp_path, max_steps=40)
    assert ds.total_episodes == 2 and ds.spec.dataset_id == "surgsim/grasp/expert-v0"
    description = ds.storage.metadata["description"]
    assert "seed 7" in description and "surgsim_envs" in description
    env = gym.make("SurgSim/Grasp-v0")
    for k, ep in enumerate(ds.iterate_episodes()):
        n = len(ep.actions)
        assert n == 40 and ep.observations.shape[0] == n + 1 and ep.truncations[-1]
        forces = ep.infos["tool_force_N"]
        assert set(forces) == set(env.unwrapped.sim.tools)
        for f in forces.values():
            assert f.shape == (n + 1, 3) and np.all(np.isfinite(f))
        assert np.abs(np.concatenate(list(forces.values()))).max() > 0.05      # the jaws closed on the organ
        assert set(ep.infos["reward_terms"]) and all(v.shape == (n + 1,) for v in ep.infos["reward_terms"].values())
        obs, _ = env.reset(seed=7 + k)
        np.testing.assert_array_equal(obs, ep.observations[0])
        for t in range(n):                                     # the recorded actions give the recorded run
            obs, reward, *_ = env.step(ep.actions[t])
            np.testing.assert_array_equal(obs, ep.observations[t + 1])
            assert reward == ep.rewards[t]
    env.close()
    with pytest.raises(ConfigError, match="already exists"):
        md.record("SurgSim/Grasp-v0", "expert", episodes=1, out=tmp_path, max_steps=2)


@pytest.mark.parametrize("kwargs, match", [
    ({"device": "joystick"}, "joystick"),
    ({"device": "policy:nowhere.npz"}, "nowhere.npz"),
    ({"episodes": 0}, "episodes=0"),
    ({"episodes": 10**9}, "episodes"),
    ({"seed": -1}, "seed=-1"),
    ({"task": "SurgSim/Nope-v0"}, "Nope"),
])
def test_bad_recordings_are_refused_with_the_value(tmp_path, kwargs, match):
    args = {"task": "SurgSim/Grasp-v0", "device": "expert", "episodes": 1, "out": tmp_path, **kwargs}
    with pytest.raises(ConfigError, match=match):
        md.record(**args)
    assert not list(tmp_path.iterdir())


def test_a_teleoperation_session_records_the_device_pose_and_the_felt_force(tmp_path):
    ds = md.record("SurgSim/Palpation-v0", "scripted", episodes=1, seed=0, out=tmp_path, max_steps=150)
    ep = next(ds.iterate_episodes())
    n = len(ep.actions)
    dev, felt, tool = ep.infos["device_position_m"], ep.infos["felt_force_N"], ep.infos["tool_force_N"]["probe"]
    assert dev.shape == (n + 1, 3) and felt.shape == (n + 1, 3) and ep.infos["device_quaternion"].shape == (n + 1, 4)
    assert dev[:-1, 2].min() < -0.005                         # the hand went down into the tissue
    np.testing.assert_allclose(felt[1:], tool[1:], atol=1e-12)  # the hand feels the probe's contact force
    assert felt[:, 2].max() > 0.02 and np.all(felt[:, 2] >= -1e-9)
    # the probe depth the task was asked for is the device's height below the probe's home
    c_hover, c_depth = 0.002, 0.008                           # Palpation-v0's hover and max_depth (m)
    press = np.clip(2.0 * -dev[:-1, 2] / (c_hover + c_depth) - 1.0, -1.0, 1.0)
    np.testing.assert_allclose(ep.actions[:, 2], press, atol=1e-6)


def test_haptic_devices_drive_only_tasks_with_a_pose_mapping(tmp_path):
    from surgsim_envs.integrations.teleop_actions import device_source

    with pytest.raises(ConfigError, match="cannot be driven by a haptic device.*Palpation-v0"):
        device_source("SurgSim/Unknown-v0", "scripted")
    with pytest.raises(ConfigError, match="nowhere.csv"):
        md.record("SurgSim/Palpation-v0", "replay:nowhere.csv", episodes=1, out=tmp_path)
    assert not list(tmp_path.iterdir())


def test_a_teleoperated_grasp_closes_with_the_grip_and_carries_the_organ_to_the_target(tmp_path):
    ds = md.record("SurgSim/Grasp-v0", "scripted", episodes=1, seed=3, out=tmp_path)
    ep = next(ds.iterate_episodes())
    felt, tool = ep.infos["felt_force_N"], ep.infos["tool_force_N"]["grasper"]
    np.testing.assert_allclose(felt[1:], tool[1:], atol=1e-12)    # the hand feels the grasper's contact force
    assert np.all(ep.actions[:, 3] == 1.0)                         # the hand squeezes the grip fully
    dev = ep.infos["device_position_m"][:-1]
    assert np.all(dev[:30] == 0.0) and np.abs(dev[-1]).max() > 0.005   # still while the jaws close, then carried
    # the episode ended because the grasped organ reached this episode's target (within tolerance 5 mm)
    assert ep.terminations[-1] and np.linalg.norm(ep.observations[-1, 3:6]) <= 0.005


def test_a_teleoperated_slippage_grip_is_the_jaw_closure(tmp_path):
    ds = md.record("SurgSim/Slippage-v0", "scripted", episodes=1, seed=0, out=tmp_path, max_steps=60)
    ep = next(ds.iterate_episodes())
    np.testing.assert_allclose(ep.infos["felt_force_N"][1:], ep.infos["tool_force_N"]["grasper"][1:], atol=1e-12)
    # the demonstration holds the settled closure (initial_closure 0.7), then tightens
    np.testing.assert_allclose(ep.actions[0, 0], 0.7, atol=1e-6)
    assert np.all(np.diff(ep.actions[:, 0]) >= -1e-6) and ep.actions[-1, 0] > 0.7


def test_teleoperated_presses_land_under_the_device(tmp_path):
    ds = md.record("SurgSim/PalpationPress-v0", "scripted", episodes=1, seed=0, out=tmp_path / "press", max_steps=10)
    ep = next(ds.iterate_episodes())
    env = gym.make("SurgSim/PalpationPress-v0")
    home, hw = env.unwrapped.home, env.unwrapped.config.map_half_width
    env.close()
    dev = ep.infos["device_position_m"][:-1]
    np.testing.assert_allclose(ep.actions[:, :2] * hw, dev[:, :2] + home[:2], atol=1e-6)
    assert np.ptp(dev[:, 0]) > 0.01                               # the hand moved between presses
    ds = md.record("SurgSim/LayeredPalpation-v0", "scripted", episodes=1, seed=0, out=tmp_path / "layered", max_steps=6)
    ep = next(ds.iterate_episodes())
    dev, felt = ep.infos["device_position_m"][:-1], ep.infos["felt_force_N"]
    depth = (ep.actions[:, 2] + 1.0) / 2.0 * 0.008                 # LayeredPalpation-v0's max_depth
    np.testing.assert_allclose(depth, -dev[:, 2], atol=1e-6)      # as deep as the hand is below the wall's top
    np.testing.assert_allclose(felt[1:, 2], ep.observations[1:, 3], rtol=1e-6)   # the probe force it read
    assert felt[1:, 2].min() > 0.0
