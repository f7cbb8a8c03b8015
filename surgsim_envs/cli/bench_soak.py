"""``surgsim bench soak``: long random-action runs of the tasks, counting NaN, exceptions,
divergences, observations outside their space, out-of-bounds forces and memory growth
(:mod:`surgsim_envs.bench.soak`).

    surgsim bench soak --task SurgSim/Grasp-v0 --steps 1000000 --json
    surgsim bench soak --task all --steps 20000 --max-seconds 600
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys

from surgsim_envs.bench.soak import FORCE_BOUND_N, soak
from surgsim_envs import validate
from surgsim_envs.errors import ConfigError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--task", default="all", help="task id (e.g. SurgSim/Grasp-v0) or 'all'; default all")
    parser.add_argument("--steps", type=int, default=10_000, help="control steps per task; default 10000")
    parser.add_argument("--seed", type=int, default=0, help="master seed (episode seeds and actions); default 0")
    parser.add_argument("--force-bound", type=float, default=FORCE_BOUND_N, help="N, peak force counted as out of bounds")
    parser.add_argument("--max-seconds", type=float, default=math.inf,
                        help="stop a task after this wall time (s) even if fewer steps ran; default no limit")
    parser.add_argument("--sample-every", type=int, default=1000, help="steps between RSS samples; default 1000")
    parser.add_argument("--json", action="store_true", help="print JSON rows instead of a table")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--workers", type=int, default=1,
                        help="processes per task, steps split across them, distinct seeds (see soak_parallel); default 1")
    parser.add_argument("--out", default=None,
                        help="JSON file of every segment and the merged counts, kept up to date (checkpoints)")
    parser.add_argument("--resume", action="store_true", help="continue the soak in --out: run only the missing steps")
    parser.add_argument("--table", default=None, metavar="FILE.json",
                        help="print the docs/benchmarks.md table of a soak --out file and exit (runs nothing)")
    parser.add_argument("--checkpoint-every", type=int, default=10_000,
                        help="steps between a worker's checkpoints of its counts; default 10000")


def run(args) -> int:
    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401

    if args.table is not None:
        from surgsim_envs.bench.soak_parallel import load_state, markdown_table

        if not os.path.isfile(args.table):
            raise ConfigError(f"--table {args.table}: no such file; give the --out JSON of a soak")
        print(markdown_table(load_state(args.table)))
        return 0
    if args.sample_every < 1:
        raise ConfigError(f"--sample-every must be >= 1, got {args.sample_every}")
    validate.seed(args.seed, "--seed")
    validate.integer(args.checkpoint_every, "--checkpoint-every", lo=1, hi=10**9, fix="steps between checkpoints, e.g. 10000")
    validate.real(args.force_bound, "--force-bound", lo=0.0, hi=1e4, lo_open=True, unit="N",
                  fix="the largest plausible tool force in (0, 1e4] N, e.g. 50")
    if args.max_seconds != math.inf:
        validate.duration(args.max_seconds, "--max-seconds", hi=30 * 86400.0,
                          fix="a wall-time limit in (0, 30 days] s, or leave it out for none")
    tasks = sorted(k for k in gym.registry if k.startswith("SurgSim/")) if args.task == "all" else [args.task]
    for t in tasks:
        if t not in gym.registry:
            raise ConfigError(f"unknown task {t!r}; choose one of {sorted(k for k in gym.registry if k.startswith('SurgSim/'))} or 'all'")
    if args.workers != 1 or args.out is not None or args.resume:
        from surgsim_envs.bench.soak_parallel import run_parallel

        if args.out is None:
            raise ConfigError("--workers > 1 and --resume need --out FILE.json (where the counts are kept)")
        validate.writable_file(args.out, "--out")
        rows = run_parallel(tasks, args.steps, args.seed, args.workers, args.out, args.resume, args.force_bound,
                            args.max_seconds, args.sample_every, args.checkpoint_every,
                            progress=not args.quiet and not args.json)
        for r in rows:  # the table's columns
            r["steps_per_s"] = r["steps"] / r["cpu_s_sum"] * min(args.workers, r["segments"]) if r["cpu_s_sum"] else math.nan
            r["rss_growth_mb"] = r["rss_growth_mb_max"] if r["rss_growth_mb_max"] is not None else math.nan
    else:
        rows = [soak(t, args.steps, args.seed, args.force_bound, args.max_seconds, args.sample_every,
                     progress=not args.quiet and not args.json) for t in tasks]
    if args.json:  # strict JSON: NaN (e.g. no RSS baseline in a run of one episode) becomes null
        from surgsim_envs.bench.soak_parallel import json_safe

        print(json.dumps([json_safe(r) for r in rows], indent=2))
    else:
        print(f"{'task':<22} {'steps':>9} {'episodes':>8} {'steps/s':>8} {'NaN':>4} {'exc':>4} {'unstable':>8} "
              f"{'obs OOB':>7} {'force OOB':>9} {'RSS growth MB':>13}")
        for r in rows:
            print(f"{r['task']:<22} {r['steps']:>9} {r['episodes']:>8} {r['steps_per_s']:>8.0f} {r['nan']:>4} "
                  f"{r['exceptions']:>4} {r['unstable']:>8} {r['obs_out_of_space']:>7} {r['force_out_of_bounds']:>9} "
                  f"{r['rss_growth_mb']:>13.1f}")
        for r in rows:
            for k, msg in r["exception_messages"].items():
                print(f"  {r['task']} {k}: {msg}", file=sys.stderr)
        print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    bad = sum(r["nan"] + r["exceptions"] + r["unstable"] + r["obs_out_of_space"] + r["force_out_of_bounds"] for r in rows)
    return 1 if bad else 0
