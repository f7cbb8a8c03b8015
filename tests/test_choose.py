"""choose(): cheapest model meeting error and cost, clear error otherwise; resolve_resolution()."""

import pytest

from surgsim_envs.bench import choose, resolve_resolution
from surgsim_envs.errors import ConfigError

ROWS = [
    {"scene": "indent", "model": "a", "integrator": "x", "spacing": 0.003, "nodes": 100, "error": 0.30, "us_per_ms": 10.0, "dt": 1e-3},
    {"scene": "indent", "model": "a", "integrator": "x", "spacing": 0.001, "nodes": 900, "error": 0.05, "us_per_ms": 400.0, "dt": 1e-3},
    {"scene": "indent", "model": "b", "integrator": "y", "spacing": 0.002, "nodes": 300, "error": 0.08, "us_per_ms": 150.0, "dt": 1e-3},
    {"scene": "indent", "model": "c", "integrator": "z", "spacing": 0.002, "nodes": 300, "error": 0.01, "us_per_ms": 5.0, "baseline": True},
]


def test_picks_cheapest_that_meets_both():
    assert choose(0.1, 1000.0, table=ROWS).model == "b"
    assert choose(0.06, 1000.0, table=ROWS).spacing == 0.001
    assert choose(0.5, 50.0, table=ROWS).model == "a"


def test_none_meets_names_closest():
    with pytest.raises(ConfigError, match="closest: b/y"):
        choose(0.07, 160.0, table=ROWS)


def test_bad_input():
    with pytest.raises(ConfigError):
        choose(-1, 100, table=ROWS)
    with pytest.raises(ConfigError):
        choose(0.1, 100, scene="nope", table=ROWS)


def test_shipped_table_and_resolve_resolution():
    pick = choose(1.0, 1e9)
    assert pick.spacing > 0 and pick.us_per_ms > 0
    model, spacing = resolve_resolution("auto", error_tolerance=1.0, step_budget_us=1e9)
    assert (model, spacing) == (pick.model, pick.spacing)
    assert resolve_resolution(0.004, model="fem") == ("fem", 0.004)
    assert resolve_resolution(None, model="fem") == ("fem", None)
    with pytest.raises(ConfigError):
        resolve_resolution("fine")
