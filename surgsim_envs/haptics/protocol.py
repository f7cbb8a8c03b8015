"""The small physics protocol the haptic servo talks to.

The servo loop never imports the MuJoCo scene; it drives any object with these members:

``dt``  (float, s)
    the physics time step.
``time`` (float, s)
    the physics clock.
``set_proxy_pose(position, quaternion)``
    move the haptic proxy (a mocap body in the scene) to ``position`` (3,) m, unit quaternion
    ``(w, x, y, z)``, in scene coordinates. Takes effect at the next :meth:`step`.
``step()``
    advance one physics step of ``dt``.
``coupling_force() -> (3,) N``
    the force **the hand feels**: the reaction of the virtual coupling (spring/weld) between the
    proxy and the simulated tool, in scene coordinates. When the tool is at rest in contact it
    equals the contact force on the tool.

Optional members the servo uses when present:
``set_grip(value)``  jaw command in [0, 1];
``contact_stiffness() -> float``  N/m, local stiffness of the hand force along its direction
(used by the stiffness extrapolator instead of estimating it).

:class:`~surgsim_envs.haptics.fake_physics.SpringWallPhysics` implements it analytically;
:mod:`surgsim_envs.haptics.scene_adapter` adapts the MuJoCo scene ``Simulation``.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class HapticPhysics(Protocol):
    """What the servo loop needs from a physics simulation (see module docstring)."""

    dt: float
    time: float

    def set_proxy_pose(self, position: np.ndarray, quaternion: np.ndarray) -> None: ...

    def step(self) -> None: ...

    def coupling_force(self) -> np.ndarray: ...


def check_physics(physics) -> None:
    """Raise :class:`~surgsim_envs.errors.ConfigError` unless ``physics`` has the protocol members."""
    from surgsim_envs.errors import ConfigError

    missing = [m for m in ("dt", "time", "set_proxy_pose", "step", "coupling_force") if not hasattr(physics, m)]
    if missing:
        raise ConfigError(
            f"{type(physics).__name__} is not a haptic physics: it lacks {missing}. "
            "Wrap a scene Simulation with surgsim_envs.haptics.scene_adapter.SceneHapticPhysics."
        )
    if not (float(physics.dt) > 0):
        raise ConfigError(f"physics dt must be > 0 s, got {physics.dt!r}")
