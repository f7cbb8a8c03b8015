"""Workers of a vector env exit when the process that made them dies.

A worker blocks reading its command pipe, and it would see the end of that pipe when the main
process dies, but with the "fork" start method every worker also inherits the write ends of
the pipes (its own included), so the read never ends: a SIGKILLed main process left its workers
and the shared-memory block behind. Here a worker asks Linux to send it SIGTERM when its parent
dies (``prctl(PR_SET_PDEATHSIG)``) and handles that SIGTERM by unlinking the shared memory it
attached and exiting. Where the parent is not the main process (the "forkserver" start method)
or prctl is unavailable, the worker polls instead: it waits for a command at most
:data:`PARENT_POLL_S` s at a time and checks that the main process is still alive.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys

#: s between checks that the main process is alive, where the kernel cannot signal its death
PARENT_POLL_S = 1.0
_PR_SET_PDEATHSIG = 1


def parent_alive(parent_pid: int) -> bool:
    """True while process ``parent_pid`` exists (a zombie counts as gone to its children: they are
    re-parented at its death, which is checked first)."""
    if os.getppid() == parent_pid:
        return True
    try:
        os.kill(parent_pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _death_signal_set() -> bool:
    """Ask the kernel for SIGTERM at the parent's death (Linux); False where that is unavailable."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def follow_parent(parent_pid: int, on_parent_death) -> bool:
    """Make this worker call ``on_parent_death()`` (which must exit) when process ``parent_pid`` dies.

    Returns True if the kernel signals the death (nothing more to do), False if the caller must
    poll :func:`parent_alive` while it waits. A SIGTERM while the parent lives (``close()``
    terminating a stuck worker) exits at once, as the default action would."""
    direct = os.getppid() == parent_pid
    if direct and _death_signal_set():
        def _on_term(signum, frame):
            if os.getppid() != parent_pid:
                on_parent_death()
            os._exit(128 + signum)

        signal.signal(signal.SIGTERM, _on_term)
        if os.getppid() != parent_pid:     # died before prctl took effect
            on_parent_death()
        return True
    if not parent_alive(parent_pid):
        on_parent_death()
    return False
