"""Shared test fixtures: where ../shared/data lives, headless rendering defaults."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

# Several workers share the cores (pytest-xdist, one per core: pytest_xdist_auto_num_workers below),
# so the linear-algebra libraries' own thread pools (OpenBLAS, MKL through the optional pypardiso,
# OpenMP) would put two threads a worker on each core; their waiting threads spin and take the
# other worker's core. One thread each: a warm subset of the default run (eight physics test files,
# two workers, 2-core AMD EPYC) took 89-92 s against 107-112 s. A value the user set is kept; numba's
# own threads (the tests of its parallel kernels need them) are not touched. Set here, before any
# test module imports numpy, and inherited by the subprocesses tests start.
if int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) > 1:
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_var, "1")

REPO = Path(__file__).resolve().parents[1]

# pytest-xdist workers (the default run uses them: pyproject's addopts) share numba's cache with
# each other and with a single-process run: the package locks numba's cache files
# (surgsim_envs/numba_cache_lock.py), so a kernel one worker compiled loads in the others.

MAX_WORKERS = 4          # each worker holds its own scenes
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
