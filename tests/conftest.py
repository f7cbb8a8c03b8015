"""Shared test fixtures: where ../shared/data lives, headless rendering defaults."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

REPO = Path(__file__).resolve().parents[1]

# pytest-xdist workers (the default run uses them: pyproject's addopts) each keep numba's compiled
# kernels in a folder of their own: .numba-cache/<worker> in the repository, or <worker> under a
# NUMBA_CACHE_DIR set by the caller. numba numbers a kernel's cache files per process, so two
# processes filling one cache at once can write one kernel's machine code under another's index
# entry, which crashed a worker. Set before any test module imports numba; numba reads it on import.
WORKER = os.environ.get("PYTEST_XDIST_WORKER")
if WORKER:
    _base = os.environ.get("NUMBA_CACHE_DIR") or str(REPO / ".numba-cache")
    os.environ["NUMBA_CACHE_DIR"] = str(Path(_base) / WORKER)
    if "numba" in sys.modules:     # a plugin imported numba first: make it read the folder again
        from numba.core import config as _numba_config

        _numba_config.reload_config()

MAX_WORKERS = 4          # each worker compiles the kernels it meets once and holds its own scenes
WORKER_MEMORY = 3 << 30  # bytes a worker may need at its peak (the largest default-run tests)


def _available_memory() -> int:
    """MemAvailable of /proc/meminfo in bytes (free memory plus what the page cache would give
    back); where there is none, as much as MAX_WORKERS need."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return WORKER_MEMORY * MAX_WORKERS


def pytest_xdist_auto_num_workers(config):
    """``-n auto``: one worker per core the process may use, at most MAX_WORKERS and at most one per
    WORKER_MEMORY of available memory (never under 1)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(cores, MAX_WORKERS, _available_memory() // WORKER_MEMORY))


SHARED_DATA = Path(os.environ.get("SURGSIM_SHARED_DATA", REPO.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """../shared/data beside the repository (reference data; not shipped)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"reference data not found at {SHARED_DATA}; set SURGSIM_SHARED_DATA or clone with ../shared beside the repo")
    return SHARED_DATA


@pytest.fixture(scope="module")
def truthcube(shared_data):
    """(scripts/truthcube.py as a module, rest bead positions (343, 3) m, {strain: measured positions})."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("truthcube_script", REPO / "scripts" / "truthcube.py")
    tc = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tc)
    rest, measured = tc.load_truthcube(shared_data / "truthcube" / "uniaxial_positions.csv")
    return tc, rest, measured


@pytest.fixture(scope="module")
def palpation():
    """A SurgSim/Palpation-v0 env shared by a test module (closed after it)."""
    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401  (registers the tasks)

    env = gym.make("SurgSim/Palpation-v0")
    yield env
    env.close()
