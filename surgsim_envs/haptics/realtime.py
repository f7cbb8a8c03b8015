"""Real-time helpers for the haptic servo thread: scheduling priority and a precise wait.

**Priority.** On a busy machine the kernel's fair scheduler can keep a woken servo thread off
the CPU for a whole time slice (3-20 ms measured on 2 shared cores), whatever the servo itself
does. :func:`raise_thread_priority` asks, for the *calling thread only*, for

1. ``SCHED_FIFO`` at priority :data:`FIFO_PRIORITY` (a real-time class: a woken FIFO thread
   preempts every normal thread on its core; Linux still throttles real-time threads to 95 % of
   a core, so a runaway loop cannot lock the machine), else
2. ``nice`` :data:`NICE_BOOST` (a larger share of the fair scheduler), else
3. nothing.

Both need a privilege (root, ``CAP_SYS_NICE`` or an ``rtprio`` limit in
``/etc/security/limits.conf``); without it the call falls back silently and returns what it
obtained (``"SCHED_FIFO"``, ``"nice -10"`` or ``"default"``), which the servo reports in its
statistics. Nothing is changed for other threads or the process.

**Waiting.** ``time.sleep`` wakes 50-100 us late on Linux, more on a loaded machine.
:func:`wait_until` sleeps until ``spin_s`` before the deadline, then polls the clock, yielding
the GIL (``time.sleep(0)``) on every poll so other Python threads keep running.
"""

from __future__ import annotations

import os
import threading
import time
from typing import Iterator

#: SCHED_FIFO priority asked for the servo thread (1-99; low: above every normal thread only)
FIFO_PRIORITY = 10
#: nice value asked when SCHED_FIFO is refused
NICE_BOOST = -10


def fifo_notice(enable: bool = True, euid: int | None = None) -> str | None:
    """The one line a command prints before a servo thread that will take ``SCHED_FIFO`` starts
    (running as root, with ``realtime_priority`` on), else None. ``euid`` defaults to the
    process's effective user id."""
    if euid is None:
        euid = os.geteuid() if hasattr(os, "geteuid") else -1
    if not enable or euid != 0 or not hasattr(os, "SCHED_FIFO"):
        return None
    return (f"running as root: the servo thread takes real-time scheduling (SCHED_FIFO, priority {FIFO_PRIORITY}; "
            "Linux caps real-time threads at 95 % of a core)")


def raise_thread_priority(enable: bool = True) -> str:
    """Raise the calling thread's scheduling priority (module docstring); returns what was
    obtained: ``"SCHED_FIFO"``, ``"nice -10"`` or ``"default"``."""
    if not enable:
        return "default"
    if hasattr(os, "sched_setscheduler") and hasattr(os, "SCHED_FIFO"):
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(FIFO_PRIORITY))  # 0: this thread
            return "SCHED_FIFO"
        except (OSError, AttributeError):
            pass
    if hasattr(os, "setpriority"):
        try:
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), NICE_BOOST)
            return f"nice {NICE_BOOST}"
        except (OSError, AttributeError):
            pass
    return "default"


def wait_until(deadline: float, spin_s: float) -> float:
    """Wait until ``time.perf_counter() >= deadline``: sleep to ``deadline - spin_s``, then
    poll; returns the clock at return."""
    now = time.perf_counter()
    if deadline - now > spin_s:
        time.sleep(deadline - now - spin_s)
        now = time.perf_counter()
    while now < deadline:
        time.sleep(0)  # releases the GIL for the physics thread
        now = time.perf_counter()
    return now


def periodic_ticks(start: float, period: float, spin_s: float, stop) -> "Iterator[float]":
    """The clock of a fixed-rate loop: yields the wall time (``time.perf_counter``) of tick i at
    ``start + i * period`` (waiting with :func:`wait_until`) until ``stop()`` is true. More than
    5 periods behind, it skips the missed ticks instead of bursting through them."""
    i = 0
    while not stop():
        deadline = start + i * period
        now = time.perf_counter()
        if deadline > now:
            now = wait_until(deadline, spin_s)
        elif now - deadline > 5 * period:
            i = int((now - start) / period)
        yield now
        i += 1
