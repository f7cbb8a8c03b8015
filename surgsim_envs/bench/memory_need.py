"""Refuse a reference solve that would not fit in this host's memory, before it starts.

The finest levels of the task-accuracy references factorise stiffness matrices of 50,000-110,000
nodes and peak at 7-17 GB. A host without that much free memory does not raise MemoryError: the
kernel's out-of-memory killer ends the process, with no message and the coarser levels' minutes
lost. :func:`require_memory` compares a level's expected peak with the memory the kernel reports as
available (``MemAvailable`` in ``/proc/meminfo``) and raises :class:`ConfigError` naming both and the
fix. Where the figure is not readable (not Linux) nothing is checked.
"""

from __future__ import annotations

from pathlib import Path

from surgsim_envs.errors import ConfigError

MEMINFO = Path("/proc/meminfo")


def available_bytes(meminfo: Path | None = None) -> float | None:
    """The memory the kernel reports as available to a new process (bytes), or None where it does not
    say (no ``/proc/meminfo``, no ``MemAvailable`` line). ``meminfo``: the file to read (default
    :data:`MEMINFO`)."""
    meminfo = MEMINFO if meminfo is None else Path(meminfo)
    try:
        text = meminfo.read_text()
    except OSError:
        return None
    for line in text.splitlines():
        if line.startswith("MemAvailable:"):
            parts = line.split()
            try:
                return float(parts[1]) * (1024.0 if parts[2:3] == ["kB"] else 1.0)
            except (IndexError, ValueError):
                return None
    return None


def require_memory(need_bytes: float, what: str, fix: str, meminfo: Path | None = None) -> None:
    """Raise ConfigError when ``need_bytes`` exceeds the available memory: ``what`` names the solve,
    ``fix`` what to do instead. Does nothing where the available memory is unknown."""
    have = available_bytes(meminfo)
    if have is not None and need_bytes > have:
        raise ConfigError(f"{what} needs about {need_bytes / 1e9:.1f} GB of memory; this host has "
                          f"{have / 1e9:.1f} GB available. {fix}")


__all__ = ["MEMINFO", "available_bytes", "require_memory"]
