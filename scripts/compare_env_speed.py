"""Env steps/s of two source trees, alternated (CHANGELOG.md, "Env step: three-pass spring kernel, env fast paths, Grasp sub-cycling").

Runs ``surgsim bench envs --json --workers 0`` with ``PYTHONPATH`` set to each tree in turn,
``--rounds`` times (A, B, A, B, ...), so both trees see the same machine load; prints per task the
median env steps/s and substep time of each tree, their ratio and the load average (``uptime``)
before and after. A tree is a directory holding ``surgsim_envs/`` (e.g. ``git archive <commit> |
tar -x -C /tmp/base``).

    MUJOCO_GL=egl python scripts/compare_env_speed.py --before /tmp/base --after . [--rounds 3]
        [--steps 200] [--repeats 3] [--tasks SurgSim/Palpation-v0,SurgSim/Grasp-v0,SurgSim/Slippage-v0]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

TASKS = "SurgSim/Palpation-v0,SurgSim/Grasp-v0,SurgSim/Slippage-v0"


def run_tree(tree: str, args) -> list[dict]:
    env = dict(os.environ, PYTHONPATH=os.path.abspath(tree), MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    cmd = [sys.executable, "-m", "surgsim_envs.cli", "bench", "envs", "--json", "--workers", "0",
           "--steps", str(args.steps), "--repeats", str(args.repeats), "--tasks", args.tasks]
    out = subprocess.run(cmd, env=env, cwd="/tmp", capture_output=True, text=True, check=True).stdout
    return json.loads(out)["envs"]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--before", required=True, help="tree A (directory with surgsim_envs/)")
    p.add_argument("--after", required=True, help="tree B")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--steps", type=int, default=200)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--tasks", default=TASKS)
    args = p.parse_args()
    for tree in (args.before, args.after):
        if not os.path.isdir(os.path.join(tree, "surgsim_envs")):
            p.error(f"{tree!r} holds no surgsim_envs/ package")
    load0 = os.getloadavg()
    runs = {"before": [], "after": []}
    for r in range(args.rounds):
        for name, tree in (("before", args.before), ("after", args.after)):
            runs[name].append(run_tree(tree, args))
            print(f"round {r + 1}/{args.rounds} {name} done, load {os.getloadavg()[0]:.1f}", file=sys.stderr)
    load1 = os.getloadavg()
    result = {"load_average_start": load0, "load_average_end": load1, "rounds": args.rounds, "tasks": {}}
    for i, task in enumerate(args.tasks.split(",")):
        row = {}
        for name in runs:
            rates = [run[i]["steps_per_s"] for run in runs[name]]
            subs = [run[i]["substep_us"] for run in runs[name]]
            row[name] = {"steps_per_s": statistics.median(rates), "all_steps_per_s": rates,
                         "substep_us": statistics.median(subs),
                         "overhead_ratio": statistics.median(run[i]["overhead_ratio"] for run in runs[name])}
        row["after_over_before"] = row["after"]["steps_per_s"] / row["before"]["steps_per_s"]
        result["tasks"][task] = row
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
