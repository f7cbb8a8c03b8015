"""Shared test fixtures: where ../shared/data lives, headless rendering defaults."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

REPO = Path(__file__).resolve().parents[1]
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
