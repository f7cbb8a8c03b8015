"""The shipped task-accuracy table: each task's force tolerance and every model's force error and cost
in that task's own scene (written by ``surgsim bench task-accuracy``; data of the tissue layer, so
``surgsim models`` and the task defaults read it without importing the bench layer).

Layout: ``{"tolerances": {task: {"tolerance": fraction, "reason": text}}, "rows": [...]}``; a row
has ``scene`` (the task id), ``model``, ``spacing`` (m), ``nodes``, ``error`` (95th percentile of
the force error against the converged reference, fraction) and ``us_per_ms`` (wall time per
simulated ms, us), or ``refused`` (why the task does not take the model).
"""

from __future__ import annotations

import json
import math
import os
from typing import Any

from surgsim_envs.errors import ConfigError

#: the shipped table
TASK_TABLE_PATH = os.path.join(os.path.dirname(__file__), "data", "task_accuracy_table.json")


def load_task_table(path: str | None = None) -> dict[str, Any]:
    """``{"tolerances": ..., "rows": ...}`` of a task-accuracy table (default: the shipped one)."""
    path = path or TASK_TABLE_PATH
    try:
        with open(path) as fh:
            data = json.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"task-accuracy table {path!r} not found; create one with "
                          "`surgsim bench task-accuracy --out DIR`") from None
    except json.JSONDecodeError as exc:
        raise ConfigError(f"task-accuracy table {path!r} is not valid JSON ({exc}); regenerate it with "
                          "`surgsim bench task-accuracy --out DIR`") from None
    if not (isinstance(data, dict) and isinstance(data.get("rows"), list) and isinstance(data.get("tolerances"), dict)):
        raise ConfigError(f"task-accuracy table {path!r} must hold {{'tolerances': {{task: ...}}, 'rows': [...]}}")
    return data


def measured(row: dict) -> bool:
    """Whether a row carries a finite error and cost (not a refusal)."""
    try:
        return "refused" not in row and all(math.isfinite(float(row[k])) for k in ("error", "us_per_ms"))
    except (KeyError, TypeError, ValueError):
        return False


def models_meeting_no_task(data: dict[str, Any]) -> dict[str, str]:
    """{model: why} for every model of the table that meets no task's tolerance at any spacing; why
    names, per task, its smallest error (and where) or the refusal."""
    tol = {v.get("scene_of", task): float(v["tolerance"]) for task, v in data["tolerances"].items()}
    best: dict[str, dict[str, dict]] = {}
    for r in data["rows"]:
        task, model = r.get("scene", r.get("task")), r.get("model")
        if task not in tol or model is None:
            continue
        seen = best.setdefault(model, {})
        if not measured(r):
            seen.setdefault(task, r)
        elif task not in seen or not measured(seen[task]) or float(r["error"]) < float(seen[task]["error"]):
            seen[task] = r
    out = {}
    for model, rows in best.items():
        if any(measured(r) and float(r["error"]) <= tol[t] for t, r in rows.items()):
            continue
        out[model] = "; ".join(
            f"{t}: {100 * float(r['error']):.0f} % at best ({1e3 * float(r['spacing']):.3g} mm; tolerance "
            f"{100 * tol[t]:.0f} %)" if measured(r) else f"{t}: refused" for t, r in sorted(rows.items()))
    return out
