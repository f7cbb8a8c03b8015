"""Adapter from the MuJoCo scene (:class:`surgsim_envs.scene.Simulation`) to the haptic physics
protocol (:mod:`surgsim_envs.haptics.protocol`), and ready-made haptic scenes per task.

Importing this module imports the scene (MuJoCo, numba); the rest of ``haptics`` does not.

* ``set_proxy_pose(p, q)`` places the scene's mocap proxy at ``p`` (m, world) with orientation
  ``q * q_home`` (the device's rotation is applied relative to the tool's home orientation, so an
  identity device quaternion keeps e.g. the grasper's axis where the scene put it);
* ``step()`` is one ``Simulation.physics_step()``;
* ``coupling_force()`` is ``Simulation.proxy_force(proxy)``: minus the weld (virtual coupling)
  force on the tool, i.e. the force the hand feels;
* ``set_grip(g)`` (graspers) maps ``g`` in [0, 1] to a jaw opening between ``open_radius`` (0)
  and ``min_radius`` (1).
"""

from __future__ import annotations

import math

import numpy as np

from surgsim_envs.errors import ConfigError

try:  # the scene is optional at haptics import time; this module needs it
    from surgsim_envs.scene import HapticProxyConfig, Simulation, make_scene, scene_config
except ImportError as exc:  # pragma: no cover - only without the scene package
    raise ImportError(f"surgsim_envs.haptics.scene_adapter needs surgsim_envs.scene ({exc})", name=exc.name) from exc

#: tasks the teleop command knows -> (scene kind, tool name)
TASKS = {"palpation": ("palpation", "probe"), "grasp": ("grasp", "grasper"), "slippage": ("grasp", "grasper")}


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


class SceneHapticPhysics:
    """A :class:`~surgsim_envs.scene.Simulation` seen through the haptic physics protocol."""

    def __init__(self, sim: "Simulation", proxy: str | None = None, grip_speed: float | None = None):
        if not isinstance(sim, Simulation):
            raise ConfigError(f"SceneHapticPhysics needs a surgsim_envs.scene.Simulation, got {type(sim).__name__}")
        if not sim.proxies:
            raise ConfigError("this scene has no haptic proxy; add HapticProxyConfig(tool=...) with the tool's drive='proxy'")
        if proxy is None:
            proxy = next(iter(sim.proxies))
        if proxy not in sim.proxies:
            raise ConfigError(f"unknown haptic proxy {proxy!r}; proxies in this scene: {sorted(sim.proxies)}")
        self.sim, self.proxy = sim, proxy
        self.tool = sim.proxies[proxy]
        self.dt = float(sim.dt)
        mid = self.tool.mocap_id
        self.home_position = np.array(sim.data.mocap_pos[mid], dtype=float)
        self.home_quat = np.array(sim.data.mocap_quat[mid], dtype=float)
        self.grip_speed = grip_speed
        self._grip = None

    @property
    def time(self) -> float:
        """Physics clock (s)."""
        return self.sim.time

    def set_proxy_pose(self, position, quaternion=(1.0, 0.0, 0.0, 0.0)) -> None:
        """Proxy at ``position`` (3,) m, device rotation ``quaternion`` relative to the home pose."""
        q = np.asarray(quaternion, dtype=float).reshape(4)
        self.sim.set_proxy_pose(self.proxy, position, _quat_mul(q, self.home_quat))

    def set_grip(self, value: float) -> None:
        """Jaw command in [0, 1] (graspers only; ignored for probes)."""
        if not self.tool.has_grip or not math.isfinite(value):
            return
        g = round(float(np.clip(value, 0.0, 1.0)), 3)
        if g == self._grip:
            return
        self._grip = g
        self.tool.set_grip(self.sim, g, speed=self.grip_speed)

    def step(self) -> None:
        """One physics step."""
        self.sim.physics_step()

    def coupling_force(self) -> np.ndarray:
        """(3,) N, the force the hand feels (world frame)."""
        return np.asarray(self.sim.proxy_force(self.proxy), dtype=float)

    def contact_force(self) -> np.ndarray:
        """(3,) N, total tissue contact force on the proxy's tool (last step)."""
        return np.asarray(self.sim.tool_force(self.tool.name), dtype=float)


def haptic_scene_config(task: str, spacing: float | None = None, model: str = "mass_spring", organ: str | None = None):
    """The task's :class:`~surgsim_envs.scene.SceneConfig` with its tool driven by a haptic proxy
    named ``"proxy"``. ``spacing`` (m) overrides the tissue node spacing, ``organ`` the volume."""
    if task not in TASKS:
        raise ConfigError(f"unknown teleop task {task!r}; choose one of {sorted(TASKS)}")
    kind, tool = TASKS[task]
    kw = {"model": model} if organ is None else {"model": model, "organ": organ}
    cfg = scene_config(kind, **kw)
    cfg.tool(tool).drive = "proxy"
    cfg.proxies = [HapticProxyConfig(name="proxy", tool=tool)]
    if spacing is not None:
        cfg.tissues[0].spacing = float(spacing)
    return cfg


def make_haptic_simulation(task: str, spacing: float | None = None, model: str = "mass_spring",
                           organ: str | None = None) -> SceneHapticPhysics:
    """Build the task's scene with a proxy-driven tool and wrap it for the servo."""
    cfg = haptic_scene_config(task, spacing=spacing, model=model, organ=organ)
    return SceneHapticPhysics(Simulation(make_scene(TASKS[task][0], cfg)))


def tissue_top(physics: SceneHapticPhysics) -> float:
    """Height (m) of the highest tissue node: where a vertical press makes contact."""
    return float(physics.sim.tissue().positions[:, 2].max())


#: the warm-up press (:func:`warm_up`): physics steps and how far below the tissue's top it goes
WARMUP_STEPS = 100
WARMUP_DEPTH = 0.002


def warm_up(physics: SceneHapticPhysics, steps: int = WARMUP_STEPS) -> None:
    """Press the proxy down to ``WARMUP_DEPTH`` below the tissue's top and back over ``steps``
    physics steps, then reset the scene: numba compiles the kernels of a press (the step loop,
    contact, the tissue step, the coupling force) now, before the servo starts, instead of in the
    first seconds of a session, where the physics would stand still while the servo runs. A few
    milliseconds once the kernels are cached."""
    home = physics.home_position.copy()
    drop = max(0.0, home[2] - (tissue_top(physics) - WARMUP_DEPTH))
    for k in range(steps):
        s = math.sin(math.pi * (k + 1) / steps)             # down, then back up
        physics.set_proxy_pose(home - np.array([0.0, 0.0, drop * s]))
        physics.step()
        physics.coupling_force()
    physics.sim.reset()

