"""One batched world seen as the single env its task's term functions read.

The single env declares its reward and termination terms once (``PalpationEnv.REWARD_TERMS``, each
``fn(env, weight)``); :class:`WorldView` gives those functions the attributes they read of world
``w`` (``config``, ``readings()``, the step's events ``new_cell`` / ``new_site`` / ``finished_now``,
the potential ``phi`` / ``phi_before``, ``error``, ``report_held``, ``steps``, ``control_dt``), so the
batched env runs the same functions rather than a second copy of their arithmetic.
"""

from __future__ import annotations

import numpy as np


class WorldView:
    """World ``w``'s per-step state (set by :meth:`point`) under the single env's attribute names."""

    def __init__(self, config, control_dt: float):
        self.config = config
        self.control_dt = control_dt

    def point(self, readings: tuple, task, steps: int, report_held: int) -> "WorldView":
        """This world's ``readings`` (probe position (3,) m, force (3,) N, depth m), its task
        bookkeeping ``task`` (events, potential, error) and counters; returns self."""
        self._readings = readings
        self.new_cell, self.new_site, self.finished_now = task.new_cell, task.new_site, task.finished_now
        self.phi, self.phi_before, self.error = task.phi, task.phi_before, task.error
        self.steps, self.report_held = int(steps), int(report_held)
        return self

    def readings(self) -> tuple[np.ndarray, np.ndarray, float]:
        return self._readings
