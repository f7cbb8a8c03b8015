"""``surgsim models``: list registered tissue models, one line each."""

from __future__ import annotations

import argparse
import json


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print {name: summary} as JSON")


def run(args: argparse.Namespace) -> int:
    from surgsim_envs.tissue import registry

    table = registry.describe()
    if args.json:
        print(json.dumps(table, indent=2))
    else:
        width = max(len(n) for n in table)
        for name, summary in table.items():
            print(f"{name:<{width}}  {summary}")
    return 0
