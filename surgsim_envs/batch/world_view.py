"""One batched world seen as the single env its task's term functions read.

The single env declares its reward and termination terms once (e.g. ``PalpationEnv.REWARD_TERMS``,
each ``fn(env, weight)``); :class:`WorldView` gives those functions the attributes they read of
world ``w`` (``config``, ``control_dt``, ``readings()``, and the task's per-step state under the
single env's attribute names: Palpation-v0's events ``new_cell`` / ``new_site`` / ``finished_now``,
potential ``phi`` / ``phi_before``, ``error``, ``report_held``, ``steps``; Grasp-v0's ``grasped``,
``progress_gain``, ``goal_dist0``, ``succeeded``, ``dropped``), so the batched env runs the same
functions rather than a second copy of their arithmetic.
"""

from __future__ import annotations


class WorldView:
    """World ``w``'s per-step state (set by :meth:`point`) under the single env's attribute names."""

    def __init__(self, config, control_dt: float):
        self.config = config
        self.control_dt = control_dt

    def point(self, readings: tuple, **state) -> "WorldView":
        """This world's ``readings`` (what the single env's ``readings()`` returns) and its per-step
        ``state`` (attribute name -> value); returns self."""
        self._readings = readings
        self.__dict__.update(state)
        return self

    def readings(self) -> tuple:
        return self._readings
