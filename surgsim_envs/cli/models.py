"""``surgsim models``: list registered tissue models, one line each; a model that meets no task's force
tolerance in the shipped task-accuracy table (:mod:`surgsim_envs.tissue.task_table`) says so."""

from __future__ import annotations

import argparse
import json


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print {name: summary} as JSON")


def run(args: argparse.Namespace) -> int:
    from surgsim_envs.tissue import registry
    from surgsim_envs.tissue.task_table import load_task_table, models_meeting_no_task

    table = registry.describe()
    short = models_meeting_no_task(load_task_table())
    table = {name: summary + (f" Meets no task's force tolerance (task-accuracy table: {short[name]})."
                              if name in short else "") for name, summary in table.items()}
    if args.json:
        print(json.dumps(table, indent=2))
    else:
        width = max(len(n) for n in table)
        for name, summary in table.items():
            print(f"{name:<{width}}  {summary}")
    return 0
