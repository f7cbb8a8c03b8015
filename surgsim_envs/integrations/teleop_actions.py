"""A haptic device drives a task through its action space, so a teleoperation session records as
a dataset with the same observations and actions an agent sees.

At each control step the device is read at the env's clock, its position is mapped into the scene
(``DeviceMapping``: origin at the tool's home, scale 1), the task's pose-to-action function turns
that target into the task's action, and after the step the contact force on the tool goes back to
the device (limited by it): the force the hand feels. The recorder keeps the device pose and the
felt force per step (:mod:`~surgsim_envs.integrations.minari_datasets`).

Devices: ``scripted`` (a demonstration trajectory for the task: down to contact, a pressed slide,
back up) and ``replay:FILE`` (a recorded hand motion, CSV/JSON, docs/haptics.md). A task takes part
with one pose-to-action function in :data:`POSE_ACTIONS`.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from surgsim_envs.errors import ConfigError


def palpation_action(env, target: np.ndarray, buttons: int) -> np.ndarray:
    """Palpation-v0 action ``[vx, vy, press, report]`` that moves the probe target towards
    ``target`` (3,) m in the scene: xy by at most ``max_xy_step`` per step, the depth from the
    target's height, report while button 0 is held."""
    u = env.unwrapped
    c = u.config
    step = float(c.max_xy_step)
    ax = np.clip((target[0] - u.target[0]) / step, -1.0, 1.0)
    ay = np.clip((target[1] - u.target[1]) / step, -1.0, 1.0)
    hover_z = u.surface_z + c.tip_radius + c.hover
    press = np.clip(2.0 * (hover_z - target[2]) / (c.hover + c.max_depth) - 1.0, -1.0, 1.0)
    return np.array([ax, ay, press, 1.0 if int(buttons) & 1 else -1.0], dtype=np.float32)


def palpation_script(env, seed: int = 0) -> dict:
    """A demonstration for Palpation-v0 in the device frame (origin at the probe's home): down
    6 mm into the tissue, a 1 cm pressed slide, back up."""
    c = env.unwrapped.config
    down = -(float(c.hover) + 0.006)
    return {"waypoints": [[0, 0, 0], [0, 0, down], [0.01, 0, down], [0, 0, 0]], "speeds": [0.01, 0.005, 0.01],
            "dwell": [0.2, 0.5, 0.3, 0.2], "seed": int(seed), "profile": "minimum_jerk"}


#: task id -> (pose-to-action function, demonstration script for the "scripted" device, tool name)
POSE_ACTIONS: dict[str, tuple[Callable, Callable, str]] = {
    "SurgSim/Palpation-v0": (palpation_action, palpation_script, "probe"),
}


def device_source(task: str, spec: str, seed: int = 0) -> Callable:
    """``factory(env) -> policy(obs)`` reading a haptic device; the policy also exposes
    ``last_device`` (position (3,) m, quaternion (4,)) and ``felt`` (force (3,) N on the hand,
    after the last step) for the recorder."""
    if task not in POSE_ACTIONS:
        raise ConfigError(f"task {task!r} cannot be driven by a haptic device yet; tasks that can: "
                          f"{sorted(POSE_ACTIONS)}. Record it with --device expert, random or policy:FILE.npz")
    from surgsim_envs.haptics.device_kinds import make_device
    from surgsim_envs.haptics.scripted import ScriptedDevice
    from surgsim_envs.haptics.servo import DeviceMapping

    to_action, script, tool = POSE_ACTIONS[task]

    def factory(env):
        u = env.unwrapped
        device = make_device(spec, scripted=lambda: ScriptedDevice(script(env, seed)), base_dir=None)
        device.connect()
        mapping = DeviceMapping(origin=tuple(float(v) for v in u.home))

        class Policy:
            last_device = (np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))
            felt = np.zeros(3)

            def __call__(self, obs):
                state = device.read(float(u.sim.time))
                self.last_device = (np.asarray(state.position, dtype=float).copy(),
                                    np.asarray(state.quaternion, dtype=float).copy())
                return to_action(env, mapping.to_scene(state.position), state.buttons)

            def after_step(self):
                force = mapping.force_to_device(u.sim.tool_force(tool))
                self.felt = np.asarray(device.send_force(force, float(u.sim.time)), dtype=float)

        return Policy()

    return factory
