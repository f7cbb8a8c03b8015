"""A haptic device drives a task through its action space, so a teleoperation session records as
a dataset with the same observations and actions an agent sees.

At each control step the device is read at the task's clock (seconds since the episode's reset),
its position is mapped into the scene (``DeviceMapping``: origin at the task's device origin,
scale 1), the task's pose-to-action function turns that target (and the device's buttons and grip)
into the task's action, and after the step the contact force on the tool goes back to the device
(limited by it): the force the hand feels. The recorder keeps the device pose and the felt force
per step (:mod:`~surgsim_envs.integrations.minari_datasets`).

Devices: ``scripted`` (a demonstration trajectory for the task) and ``replay:FILE`` (a recorded
hand motion, CSV/JSON, docs/haptics.md). A task takes part with one :class:`TeleopBinding` in
:data:`POSE_ACTIONS`:

=========================  ======================  ==========================================
task                       device frame origin      what the device commands
=========================  ======================  ==========================================
Palpation-v0               the probe's home         probe target (xy rate-limited), depth from
                                                    the height, report = button 0
PalpationPress-v0          the probe's home         press site = device xy (one press per second
                                                    of the device's clock); report = button 0
Grasp-v0                   the wrist's home         wrist target (rate-limited); jaws = grip
Slippage-v0                the wrist's home         jaw closure = grip (the pull is the task's)
LayeredPalpation-v0        probe touching the top   press site = xy; depth = height below 0;
                                                    commit = button 0 (``control_hz`` presses per
                                                    second of the device's clock)
=========================  ======================  ==========================================
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from surgsim_envs.errors import ConfigError


@dataclass(frozen=True)
class TeleopBinding:
    """How a haptic device drives one task.

    to_action(env, target, state) -> action: ``target`` (3,) m is the device position in the scene,
    ``state`` the :class:`~surgsim_envs.haptics.device.DeviceState` (buttons, grip);
    script(env, seed) -> trajectory dict (device frame) for the ``scripted`` device;
    origin(env) -> (3,) m: the scene point the device frame's origin maps to;
    felt(env) -> (3,) N: the contact force on the tool after the step (what the hand feels);
    clock(env) -> s: the task's clock, read after reset as the device's zero."""

    to_action: Callable
    script: Callable
    origin: Callable
    felt: Callable
    clock: Callable


def _unit(v: float) -> float:
    return float(np.clip(v, -1.0, 1.0))


def _grip_action(state) -> float:
    """A grip in [0, 1] (0 open, 1 closed) as a jaw action in [-1, 1]."""
    return _unit(2.0 * float(state.grip) - 1.0)


def _report(state) -> float:
    return 1.0 if int(state.buttons) & 1 else -1.0


# -- Palpation-v0 ----------------------------------------------------------------------------------
def palpation_action(env, target: np.ndarray, state) -> np.ndarray:
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
    return np.array([ax, ay, press, _report(state)], dtype=np.float32)


def palpation_script(env, seed: int = 0) -> dict:
    """A demonstration for Palpation-v0 in the device frame (origin at the probe's home): down
    6 mm into the tissue, a 1 cm pressed slide, back up."""
    c = env.unwrapped.config
    down = -(float(c.hover) + 0.006)
    return {"waypoints": [[0, 0, 0], [0, 0, down], [0.01, 0, down], [0, 0, 0]], "speeds": [0.01, 0.005, 0.01],
            "dwell": [0.2, 0.5, 0.3, 0.2], "seed": int(seed), "profile": "minimum_jerk"}


# -- PalpationPress-v0 -----------------------------------------------------------------------------
def press_action(env, target: np.ndarray, state) -> np.ndarray:
    """PalpationPress-v0 action ``[x, y, report]``: the next press lands under the device (its xy
    over ``map_half_width``); report while button 0 is held."""
    hw = float(env.unwrapped.config.map_half_width)
    return np.array([_unit(target[0] / hw), _unit(target[1] / hw), _report(state)], dtype=np.float32)


def press_script(env, seed: int = 0) -> dict:
    """The hand goes once round a square of half side 0.6 x ``map_half_width`` about the map's
    centre over the episode's presses (the task's device clock runs one second per press)."""
    u = env.unwrapped
    h = 0.6 * float(u.config.map_half_width)
    x0, y0 = -float(u.home[0]), -float(u.home[1])      # the map's centre in the device frame
    pts = [[x0 - h, y0 - h, 0], [x0 + h, y0 - h, 0], [x0 + h, y0 + h, 0], [x0 - h, y0 + h, 0], [x0 - h, y0 - h, 0]]
    return {"waypoints": pts, "speeds": 8.0 * h / float(u.config.max_presses), "dwell": 0.0, "seed": int(seed),
            "profile": "minimum_jerk"}


# -- Grasp-v0 --------------------------------------------------------------------------------------
def grasp_action(env, target: np.ndarray, state) -> np.ndarray:
    """Grasp-v0 action ``[dx, dy, dz, jaws]``: the wrist target moves towards ``target`` by at most
    ``max_step`` per step and axis; the jaws close with the grip (0 open, 1 at ``min_radius``)."""
    u = env.unwrapped
    step = float(u.config.max_step)
    d = (np.asarray(target, dtype=float) - u.target) / step
    return np.array([_unit(d[0]), _unit(d[1]), _unit(d[2]), _grip_action(state)], dtype=np.float32)


def grasp_script(env, seed: int = 0) -> dict:
    """Squeeze the grip at once and hold still 0.6 s while the jaws close (at their own closing
    speed), then carry the organ to this episode's target at half the task's top speed."""
    u = env.unwrapped
    goal = (u.goal - u.home).tolist()
    speed = 0.5 * float(u.config.max_step) * float(u.config.control_hz)
    return {"waypoints": [[0, 0, 0], goal], "speeds": speed, "dwell": [0.6, 0.5], "grip": 1.0, "seed": int(seed),
            "profile": "minimum_jerk"}


# -- Slippage-v0 -----------------------------------------------------------------------------------
def slippage_action(env, target: np.ndarray, state) -> np.ndarray:
    """Slippage-v0 action ``[closure]`` = the grip (0 fully open, 1 closed); the pull is the task's."""
    return np.array([_grip_action(state)], dtype=np.float32)


def slippage_script(env, seed: int = 0) -> dict:
    """Hold the grasp the task settled with, then tighten to full closure over the episode as the
    pull grows."""
    u = env.unwrapped
    start = (float(u.config.initial_closure) + 1.0) / 2.0
    seconds = float(u.config.episode_seconds)
    return {"waypoints": [[0, 0, 0], [0, 0, 0]], "speeds": 1.0, "dwell": [0.3 * seconds, 0.7 * seconds],
            "grip": [start, 1.0], "seed": int(seed), "profile": "minimum_jerk"}


# -- LayeredPalpation-v0 ---------------------------------------------------------------------------
def layered_action(env, target: np.ndarray, state) -> np.ndarray:
    """LayeredPalpation-v0 action ``[x, y, depth, commit]``: the press under the device's xy, as deep
    as the device is below the wall's top (clipped to ``max_depth``); commit while button 0 is held."""
    u = env.unwrapped
    c = u.config
    depth = float(np.clip(u.z_top + c.probe_radius - target[2], 0.0, c.max_depth))
    return np.array([_unit(target[0] / (0.5 * c.size[0])), _unit(target[1] / (0.5 * c.size[1])),
                     _unit(2.0 * depth / c.max_depth - 1.0), _report(state)], dtype=np.float32)


def layered_script(env, seed: int = 0) -> dict:
    """A 3 mm deep sweep along x across the middle of the patch and back."""
    c = env.unwrapped.config
    x = 0.35 * float(c.size[0])
    return {"waypoints": [[-x, 0, -0.003], [x, 0, -0.003], [-x, 0, -0.003]], "speeds": 0.5 * x * float(c.control_hz),
            "dwell": 0.0, "seed": int(seed), "profile": "minimum_jerk"}


def _tool_force(tool: str) -> Callable:
    return lambda env: env.unwrapped.sim.tool_force(tool)


def _sim_clock(env) -> float:
    return float(env.unwrapped.sim.time)


def _home(env) -> np.ndarray:
    return np.asarray(env.unwrapped.home, dtype=float)


#: task id -> how a haptic device drives it
POSE_ACTIONS: dict[str, TeleopBinding] = {
    "SurgSim/Palpation-v0": TeleopBinding(palpation_action, palpation_script, _home, _tool_force("probe"), _sim_clock),
    "SurgSim/PalpationPress-v0": TeleopBinding(press_action, press_script, _home, _tool_force("probe"),
                                               lambda env: float(env.unwrapped.steps)),   # one press per second
    "SurgSim/Grasp-v0": TeleopBinding(grasp_action, grasp_script, _home,
                                      lambda env: env.unwrapped.sim.tool_force(env.unwrapped.tool_name), _sim_clock),
    "SurgSim/Slippage-v0": TeleopBinding(slippage_action, slippage_script, _home,
                                         lambda env: env.unwrapped.sim.tool_force(env.unwrapped.tool_name), _sim_clock),
    "SurgSim/LayeredPalpation-v0": TeleopBinding(
        layered_action, layered_script,
        lambda env: np.array([0.0, 0.0, env.unwrapped.z_top + env.unwrapped.config.probe_radius]),
        lambda env: np.array([0.0, 0.0, max(float(env.unwrapped.probe.force()[2]), 0.0)]),
        lambda env: env.unwrapped.steps / float(env.unwrapped.config.control_hz)),
}


def device_source(task: str, spec: str, seed: int = 0) -> Callable:
    """``factory(env) -> policy(obs)`` reading a haptic device; made after each reset, so the
    device's clock starts at the episode's start. The policy also exposes ``last_device`` (position
    (3,) m, quaternion (4,)) and ``felt`` (force (3,) N on the hand, after the last step) for the
    recorder."""
    if task not in POSE_ACTIONS:
        raise ConfigError(f"task {task!r} cannot be driven by a haptic device yet; tasks that can: "
                          f"{sorted(POSE_ACTIONS)}. Record it with --device expert, random or policy:FILE.npz")
    from surgsim_envs.haptics.device_kinds import make_device
    from surgsim_envs.haptics.scripted import ScriptedDevice, TrajectorySpec
    from surgsim_envs.haptics.servo import DeviceMapping

    binding = POSE_ACTIONS[task]

    def factory(env):
        device = make_device(spec, scripted=lambda: ScriptedDevice(TrajectorySpec.from_dict(binding.script(env, seed))),
                             base_dir=None)
        device.connect()
        mapping = DeviceMapping(origin=tuple(float(v) for v in binding.origin(env)))
        t0 = binding.clock(env)

        class Policy:
            last_device = (np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))
            felt = np.zeros(3)

            def __call__(self, obs):
                state = device.read(binding.clock(env) - t0)
                self.last_device = (np.asarray(state.position, dtype=float).copy(),
                                    np.asarray(state.quaternion, dtype=float).copy())
                return binding.to_action(env, mapping.to_scene(state.position), state)

            def after_step(self):
                force = mapping.force_to_device(binding.felt(env))
                self.felt = np.asarray(device.send_force(force, binding.clock(env) - t0), dtype=float)

        return Policy()

    return factory
