"""A task's cheapest tissue model and resolution within its force tolerance.

:func:`choose_task_model` applies the rule of :func:`surgsim_envs.tissue.resolution.choose`
(documented there and in docs/benchmarks.md, "Speed against accuracy") to a task: its force tolerance and the rows of the
shipped task-accuracy table (:mod:`surgsim_envs.tissue.task_table`, written by ``surgsim bench
task-accuracy``; docs/task_accuracy.md), where the error is measured in the task's own scene.
"""

from __future__ import annotations


from surgsim_envs import validate
from surgsim_envs.errors import ConfigError
from surgsim_envs.tissue.resolution import Choice, choose
from surgsim_envs.tissue.task_table import TASK_TABLE_PATH, load_task_table, measured

__all__ = ["TASK_TABLE_PATH", "choose_task_model", "task_tolerance"]


def task_tolerance(task_id: str, table: str | dict | None = None) -> float:
    """The force tolerance (fraction, p95 force error against the converged reference) ``task_id``
    declares in the task-accuracy table."""
    data = table if isinstance(table, dict) else load_task_table(table)
    tolerances = data["tolerances"]
    if task_id not in tolerances:
        raise ConfigError(f"task {task_id!r} declares no force tolerance in the task-accuracy table; tasks with one: "
                          f"{sorted(tolerances)} (add a probe set and a tolerance in surgsim_envs/bench/task_accuracy.py "
                          "and rerun `surgsim bench task-accuracy`)")
    return float(tolerances[task_id]["tolerance"])


def choose_task_model(task_id: str, tolerance: float | None = None, *, table: str | dict | None = None,
                      models=None) -> Choice:
    """The cheapest (model, spacing) whose force error in ``task_id``'s own scene is within
    ``tolerance`` (fraction; default the task's declared one), from the task-accuracy table
    (default: the shipped one). ``models``: restrict to these names. ConfigError names the closest
    row when none meets it."""
    data = table if isinstance(table, dict) else load_task_table(table)
    tol = task_tolerance(task_id, data) if tolerance is None else validate.positive(
        tolerance, "tolerance", fix="a fraction of the reference force, e.g. 0.1 for 10 %")
    scene = data["tolerances"].get(task_id, {}).get("scene_of", task_id)   # a task measured in another's scene
    rows = [r for r in data["rows"] if r.get("scene") == scene and measured(r)
            and (models is None or r["model"] in set(models))]
    if not rows:
        raise ConfigError(f"the task-accuracy table has no measured rows for {task_id!r}"
                          + (f" and models {sorted(models)}" if models is not None else "")
                          + "; run `surgsim bench task-accuracy --tasks " + task_id + "`")
    try:
        return choose(tol, 1e300, scene, table=rows)
    except ConfigError:
        best = min(rows, key=lambda r: r["error"])
        raise ConfigError(f"no model meets {task_id}'s force tolerance {100 * tol:.3g} % in the task-accuracy table; "
                          f"closest: {best['model']} at {best['spacing'] * 1e3:.3g} mm with {100 * best['error']:.3g} % "
                          "(loosen the tolerance or add finer spacings to the probe set)") from None
