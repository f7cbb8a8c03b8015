"""The arrays a scene's step loops work on, bound once per :class:`~surgsim_envs.scene.simulation.Simulation`
(MjData views and the simulation's own buffers: none is ever replaced, only written in place)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class StepBuffers(NamedTuple):
    """gather: the arguments of :func:`~surgsim_envs.scene.step.kernels.gather_geoms` (geom ids,
    their bodies and root bodies, the tool bodies, MjData geom_xpos, geom_xmat, cvel, subtree_com,
    xipos, then the outputs: geom positions (G,3) m, orientations (G,9), velocities (G,6) [w rad/s,
    v m/s], tool body centres of mass (T,3) m). ctrl: MjData ctrl; goal, rate: the actuator targets'
    goals and rate limits (units of each actuator per s); xfrc: MjData xfrc_applied; bodies: the tool
    body ids (T,); wrench: (T,6) [N, N m] the reaction being summed."""

    gather: tuple
    ctrl: np.ndarray
    goal: np.ndarray
    rate: np.ndarray
    xfrc: np.ndarray
    bodies: np.ndarray
    wrench: np.ndarray

    @property
    def geom_positions(self) -> np.ndarray:
        """(G,3) m, the tool geom positions (gather's output)."""
        return self.gather[9]
