"""``surgsim choose TASK``: the cheapest tissue model and lattice spacing whose forces meet a task's
force tolerance in the shipped task-accuracy table (docs/task_accuracy.md), and the ``gym.make`` call
that builds it; a task with no qualifying row is refused with the closest one."""

from __future__ import annotations

import argparse
import json


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("task", help="a task id, e.g. SurgSim/Palpation-v0")
    parser.add_argument("--tolerance", type=float, default=None,
                        help="p95 force error as a fraction (default: the task's declared tolerance)")
    parser.add_argument("--models", default=None, help="comma-separated models to choose from (default: all)")
    parser.add_argument("--json", action="store_true", help="print the choice as JSON")


def run(args: argparse.Namespace) -> int:
    from surgsim_envs.bench.choose import choose_task_model, task_tolerance
    from surgsim_envs.envs.registry import task_spec

    spec = task_spec(args.task)                   # ConfigError naming the known tasks
    models = None if args.models is None else [m.strip() for m in args.models.split(",") if m.strip()]
    c = choose_task_model(args.task, args.tolerance, models=models)
    tolerance = task_tolerance(args.task) if args.tolerance is None else float(args.tolerance)
    # the task's own name for its lattice spacing: the one its quick settings use
    key = "resolution" if "resolution" in (spec.quick or {}) else "spacing"
    make = f'gym.make("{args.task}", model="{c.model}", {key}={c.spacing:.6g})'
    out = {"task": args.task, "tolerance": tolerance, "model": c.model, "spacing_m": c.spacing, "nodes": c.nodes,
           "error_p95": c.error, "us_per_simulated_ms": c.us_per_ms, "default_model": spec.model, "gym_make": make}
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    default = " (the task's default model)" if c.model == spec.model else f" (the task's default is {spec.model})"
    print(f"{args.task}: {c.model} at {1e3 * c.spacing:.3g} mm{default}: p95 force error {100 * c.error:.3g} % "
          f"against the reference (tolerance {100 * tolerance:.3g} %), {c.us_per_ms:.0f} us per simulated ms in the "
          f"table's presses, {c.nodes} nodes\n  {make}")
    return 0
