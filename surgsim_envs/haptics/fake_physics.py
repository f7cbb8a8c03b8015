"""A small analytic physics for haptics tests and benchmarks: a tool coupled to the hand, pressing
on a spring wall.

* The wall fills ``z < wall_z`` (normal ``+z``); it pushes the tool tip with
  ``F_contact = k_wall * max(0, wall_z - z_tool) * e_z`` (N).
* The tool (point mass ``tool_mass`` kg) is tied to the haptic proxy (position ``p``) by the
  virtual coupling: spring ``k_coupling`` (N/m) plus damping ``c`` (N s/m) on the tool velocity,
  like a MuJoCo weld to a mocap body (the mocap body has no velocity).
* The hand feels the coupling spring's reaction ``F_hand = k_coupling * (x_tool - p)``.

Coupling error (documented, tested): from the tool's equation of motion
``m a = k_c (p - x) - c v + F_contact`` it follows exactly that
``F_hand - F_contact = -(m a + c v)``, so ``|F_hand - F_contact| <= m |a| + c |v|``. Pressing at a
steady hand speed ``v_h`` the tool moves at ``v_h * k_c / (k_c + k_wall)`` and the error is
``c * v_h * k_c / (k_c + k_wall) <= c * v_h``; at rest it is zero. In contact the hand feels the
series stiffness ``k_c k_wall / (k_c + k_wall)`` times the proxy's depth below the wall.

Integration: semi-implicit (symplectic) Euler, stable for ``dt < 2 / omega`` with
``omega = sqrt((k_c + k_wall) / m)`` (the constructor checks ``dt`` against ``1 / omega``).
``work_seconds`` busy-waits per step to emulate an expensive physics (benchmarks only).
"""

from __future__ import annotations

import math
import time as _time

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError


class SpringWallPhysics:
    """Tool + coupling + spring wall (see module docstring). Implements ``HapticPhysics``."""

    def __init__(self, k_wall: float = 500.0, k_coupling: float = 2000.0, tool_mass: float = 0.02,
                 damping_ratio: float = 0.7, dt: float = 1e-3, wall_z: float = 0.0,
                 start_position=(0.0, 0.0, 0.02), work_seconds: float = 0.0):
        for name, v in (("k_wall", k_wall), ("k_coupling", k_coupling), ("tool_mass", tool_mass), ("dt", dt)):
            validate.positive(v, f"SpringWallPhysics {name}", fix="give a positive number in SI units (N/m, kg, s)")
        if not (math.isfinite(damping_ratio) and damping_ratio >= 0):
            raise ConfigError(f"damping_ratio must be >= 0, got {damping_ratio!r}")
        omega = math.sqrt((k_coupling + k_wall) / tool_mass)
        if dt * omega > 1.0:
            raise ConfigError(
                f"SpringWallPhysics dt={dt} s is too large for omega={omega:.1f} rad/s; use dt <= {1.0 / omega:.2e} s "
                "or a heavier tool / softer springs"
            )
        self.k_wall, self.k_coupling, self.tool_mass = float(k_wall), float(k_coupling), float(tool_mass)
        self.damping = 2.0 * damping_ratio * math.sqrt(k_coupling * tool_mass)
        self.dt, self.wall_z = float(dt), float(wall_z)
        self.work_seconds = float(work_seconds)
        self.time = 0.0
        self.x = np.asarray(start_position, dtype=float).reshape(3).copy()
        self.v = np.zeros(3)
        self.proxy = self.x.copy()
        self.proxy_quat = np.array([1.0, 0.0, 0.0, 0.0])
        self.grip = 0.0
        self.steps = 0

    @property
    def series_stiffness(self) -> float:
        """N/m felt by the hand per metre of proxy depth below the wall (quasi-static)."""
        return self.k_coupling * self.k_wall / (self.k_coupling + self.k_wall)

    def set_proxy_pose(self, position, quaternion=(1.0, 0.0, 0.0, 0.0)) -> None:
        """Proxy target (3,) m and quaternion ``(w, x, y, z)``."""
        p = np.asarray(position, dtype=float).reshape(3)
        if not np.all(np.isfinite(p)):
            raise ConfigError(f"proxy position must be finite, got {p!r}")
        self.proxy = p.copy()
        self.proxy_quat = np.asarray(quaternion, dtype=float).reshape(4).copy()

    def set_grip(self, value: float) -> None:
        """Jaw command in [0, 1] (stored only)."""
        self.grip = float(value)

    def contact_force(self) -> np.ndarray:
        """Force of the wall on the tool (3,) N."""
        pen = self.wall_z - self.x[2]
        return np.array([0.0, 0.0, self.k_wall * pen if pen > 0 else 0.0])

    def coupling_force(self) -> np.ndarray:
        """Force on the hand (3,) N: ``k_coupling * (x_tool - proxy)``."""
        return self.k_coupling * (self.x - self.proxy)

    def contact_stiffness(self) -> float:
        """N/m of the hand force along its direction: the series stiffness in contact, else 0."""
        return self.series_stiffness if self.x[2] < self.wall_z else 0.0

    def step(self) -> None:
        """Advance one step of ``dt`` (semi-implicit Euler)."""
        if self.work_seconds > 0:
            end = _time.perf_counter() + self.work_seconds
            while _time.perf_counter() < end:
                pass
        f = self.k_coupling * (self.proxy - self.x) - self.damping * self.v + self.contact_force()
        self.v = self.v + self.dt * f / self.tool_mass
        self.x = self.x + self.dt * self.v
        self.time += self.dt
        self.steps += 1

    def acceleration(self) -> np.ndarray:
        """Current tool acceleration (3,) m/s^2 (from the forces at the current state)."""
        f = self.k_coupling * (self.proxy - self.x) - self.damping * self.v + self.contact_force()
        return f / self.tool_mass
