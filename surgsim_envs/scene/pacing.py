"""Pace a loop to real time: ``render_mode="human"`` shows one env step per control period.

Without pacing a 100 Hz task ran about ten times faster than real time in the viewer (19,285
steps in 20 s). :class:`RealTimePacer` sleeps, after each step, until that step's slot of
``period_s`` has passed. A step that overruns its slot is not made up by running the next ones
faster: when the loop falls more than one period behind, the schedule restarts from now (no
burst of unpaced steps after a pause, e.g. a breakpoint or a slow reset). The clock and the
sleep are injectable, so the schedule is tested with a fake clock.
"""

from __future__ import annotations

import math
import time
from typing import Callable

from surgsim_envs.errors import ConfigError


class RealTimePacer:
    """``wait()`` after every step holds the loop to one step per ``period_s`` seconds."""

    def __init__(self, period_s: float, clock: Callable[[], float] = time.perf_counter,
                 sleep: Callable[[float], None] = time.sleep):
        if not (isinstance(period_s, (int, float)) and math.isfinite(period_s) and period_s > 0):
            raise ConfigError(f"pacing period {period_s!r} s must be a finite number > 0")
        self.period_s = float(period_s)
        self.clock, self.sleep = clock, sleep
        self._next: float | None = None
        self.slept_s = 0.0          # total time slept (diagnostics)
        self.restarts = 0           # how often the loop fell behind and the schedule restarted

    def reset(self) -> None:
        """Forget the schedule: the next ``wait()`` starts a new one (e.g. after ``env.reset``)."""
        self._next = None

    def wait(self) -> float:
        """Sleep until this step's slot ends; returns the seconds slept."""
        now = self.clock()
        if self._next is None:
            self._next = now + self.period_s
            return 0.0
        delay = self._next - now
        if delay > 0:
            self.sleep(delay)
            self.slept_s += delay
            self._next += self.period_s
            return delay
        if -delay > self.period_s:          # more than a period behind: restart, do not catch up
            self._next = now + self.period_s
            self.restarts += 1
        else:
            self._next += self.period_s
        return 0.0


def pace_period(control_hz: float, pace: float | None) -> float | None:
    """Seconds per env step for ``pace`` x real time (None: unpaced)."""
    if pace is None:
        return None
    if not (isinstance(pace, (int, float)) and not isinstance(pace, bool) and math.isfinite(pace) and pace > 0):
        raise ConfigError(f"human_pace={pace!r}: give a speed factor > 0 (1.0 = real time, 2.0 = twice as fast) "
                          "or None to run unpaced")
    return 1.0 / (float(control_hz) * float(pace))
