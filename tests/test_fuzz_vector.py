"""Hostile options and actions of the SurgSim vector env: refused by name before any worker
starts (options) or before the step is sent (actions), or working with finite results."""

from __future__ import annotations

import pytest

pytest.importorskip("hypothesis", reason="hypothesis is in the [test] extra")
from hypothesis import HealthCheck, given, settings  # noqa: E402

import fuzz_surfaces as fs  # noqa: E402
from fuzz_harness import check  # noqa: E402


@settings(max_examples=5, deadline=None, database=None, suppress_health_check=list(HealthCheck))
@given(fs.vector_case())
def test_fuzz_vector_options_and_actions(case):
    check(fs.run_vector, case, timeout_s=60)


@pytest.mark.slow
@settings(max_examples=400, deadline=None, database=None, suppress_health_check=list(HealthCheck))
@given(fs.vector_case())
def test_fuzz_vector_options_and_actions_more(case):
    check(fs.run_vector, case, timeout_s=60)
