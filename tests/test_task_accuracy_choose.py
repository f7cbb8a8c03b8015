"""choose_task_model(): a task's cheapest model within its declared force tolerance, from the
task-accuracy table; `surgsim models` names models that meet no task's tolerance."""

from __future__ import annotations

import pytest

from surgsim_envs.bench.choose import choose_task_model, task_tolerance
from surgsim_envs.errors import ConfigError
from surgsim_envs.tissue.task_table import load_task_table, models_meeting_no_task


def _row(model, spacing, error, cost, task="T"):
    return {"scene": task, "task": task, "model": model, "integrator": "default", "spacing": spacing, "nodes": 10,
            "error": error, "us_per_ms": cost, "dt": 1e-3}


TABLE = {"tolerances": {"T": {"tolerance": 0.10, "reason": "test"}, "U": {"tolerance": 0.5, "reason": "test"}},
         "rows": [_row("cheap", 0.01, 0.40, 10.0), _row("good", 0.01, 0.08, 50.0), _row("good", 0.005, 0.03, 400.0),
                  _row("never", 0.005, 0.60, 5.0), _row("never", 0.005, 0.70, 5.0, task="U"),
                  {"scene": "T", "task": "T", "model": "refused_one", "spacing": 0.01, "refused": "no forces"}]}


def test_the_declared_tolerance_picks_the_cheapest_model_within_it():
    assert task_tolerance("T", TABLE) == 0.10
    pick = choose_task_model("T", table=TABLE)
    assert (pick.model, pick.spacing) == ("good", 0.01)
    assert choose_task_model("T", 0.05, table=TABLE).spacing == 0.005      # tighter: finer
    assert choose_task_model("T", 0.5, table=TABLE).model == "cheap"       # looser: cheaper


def test_no_model_within_the_tolerance_names_the_closest_and_unknown_tasks_are_refused():
    with pytest.raises(ConfigError, match=r"closest: good at 5 mm with 3 %"):
        choose_task_model("T", 0.01, table=TABLE)
    with pytest.raises(ConfigError, match="declares no force tolerance"):
        choose_task_model("SurgSim/Nope-v0", table=TABLE)
    with pytest.raises(ConfigError, match="tolerance"):
        choose_task_model("T", -0.1, table=TABLE)


def test_models_that_meet_no_task_are_named_with_their_best_errors():
    short = models_meeting_no_task(TABLE)
    assert set(short) == {"cheap", "never", "refused_one"}
    assert "T: 60 %" in short["never"] and "U: 70 %" in short["never"]


def test_the_shipped_table_declares_tolerances_and_its_choices_meet_them():
    data = load_task_table()
    assert data["tolerances"], "the shipped task-accuracy table declares no task tolerance"
    for task, spec in data["tolerances"].items():
        assert spec["reason"]
        scene = spec.get("scene_of", task)
        rows = [r for r in data["rows"] if r.get("scene") == scene and "error" in r]
        within = [r for r in rows if r["error"] <= spec["tolerance"]]
        if not within:                                   # none meets it: the refusal names the closest
            with pytest.raises(ConfigError, match="closest"):
                choose_task_model(task)
            continue
        pick = choose_task_model(task)
        assert pick.error <= spec["tolerance"]
        assert pick.us_per_ms == min(r["us_per_ms"] for r in within)


def test_surgsim_models_says_which_models_meet_no_task_tolerance(capsys):
    import argparse

    from surgsim_envs.cli import models as models_cmd

    short = models_meeting_no_task(load_task_table())
    assert models_cmd.run(argparse.Namespace(json=True)) == 0
    import json

    described = json.loads(capsys.readouterr().out)
    for name, text in described.items():
        assert ("Meets no task's force tolerance" in text) == (name in short), name
