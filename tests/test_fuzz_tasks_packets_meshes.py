"""Hostile actions on every task, UDP pose datagrams (keyed and not) and damaged mesh files, drawn
from the same strategies as scripts/fuzz_counts.py's table: each is refused with the project's
error (a ConfigError, a ValueError subclass) or works with finite results; never a raw
exception, NaN or a hang. Bounded examples here, more under ``-m slow``."""

from __future__ import annotations

import gymnasium as gym
import pytest

pytest.importorskip("hypothesis", reason="hypothesis is in the [test] extra")
from hypothesis import HealthCheck, given, settings  # noqa: E402

import fuzz_surfaces as fs  # noqa: E402
from fuzz_harness import check  # noqa: E402

import surgsim_envs.envs  # noqa: E402,F401  (registers the tasks)

FAST = settings(max_examples=60, deadline=None, database=None, suppress_health_check=list(HealthCheck))
MORE = settings(max_examples=2000, deadline=None, database=None, suppress_health_check=list(HealthCheck))
ENV = settings(max_examples=25, deadline=None, database=None, suppress_health_check=list(HealthCheck))


@pytest.fixture(scope="module")
def task_envs():
    envs = {task: gym.make(f"SurgSim/{task}") for task in fs.ACTION_TASKS}
    for env in envs.values():
        env.reset(seed=0)
    yield envs
    for env in envs.values():
        env.close()


@ENV
@given(fs.task_action_case())
def test_fuzz_actions_of_every_task(task_envs, case):
    check(fs.run_task_action, task_envs, case, timeout_s=60)


@FAST
@given(fs.udp_case())
def test_fuzz_udp_datagrams(case):
    check(fs.run_udp, case, timeout_s=10)


@FAST
@given(fs.mesh_case())
def test_fuzz_mesh_files(case):
    check(fs.run_mesh, case, timeout_s=30)


@pytest.mark.slow
@MORE
@given(fs.udp_case())
def test_fuzz_udp_datagrams_more(case):
    check(fs.run_udp, case, timeout_s=10)


@pytest.mark.slow
@MORE
@given(fs.mesh_case())
def test_fuzz_mesh_files_more(case):
    check(fs.run_mesh, case, timeout_s=30)
