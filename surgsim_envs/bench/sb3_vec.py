"""``surgsim bench sb3-vec``: stable-baselines3 vector env throughput, DummyVecEnv (1 env, in
process) against SubprocVecEnv with 2, 4, ... worker processes (how SB3 training
scales on this machine's cores). Env steps per second, median over ``--repeats`` timed blocks
of ``--steps`` steps each (random actions, after a warm-up), all in one process run so the
ratios share the machine load. Needs the [train] extra (stable-baselines3).

    surgsim bench sb3-vec --task SurgSim/PalpationPress-v0 --workers 1,2,4 --steps 40 --repeats 3
"""

from __future__ import annotations

import json
import os
import statistics
import time

import numpy as np

from surgsim_envs.errors import ConfigError


def add_arguments(p) -> None:
    p.add_argument("--task", default="SurgSim/Grasp-v0")
    p.add_argument("--workers", default="1,2,4", help="comma list; 1 = DummyVecEnv, n > 1 = SubprocVecEnv(n)")
    p.add_argument("--steps", type=int, default=200, help="env steps per timed block (all workers together)")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--shared", action="store_true",
                   help="also time SB3VectorEnv (surgsim_envs/integrations/sb3.py, shared-memory workers) for each n > 1")
    p.add_argument("--json", action="store_true")


def rate(task: str, n: int, steps: int, repeats: int, shared: bool = False) -> float:
    """Median env steps/s of an SB3 vector env of ``n`` copies of ``task`` (``shared``: SB3VectorEnv
    wrapped in VecMonitor, else make_vec_env's DummyVecEnv for n = 1 and SubprocVecEnv)."""
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    if shared:
        from surgsim_envs.integrations.sb3 import make_sb3_vec_env

        venv = make_sb3_vec_env(task, n, seed=0, env_kwargs={"on_unstable": "terminate"})
    else:
        venv = make_vec_env(f"surgsim_envs:{task}", n_envs=n, seed=0,
                            vec_env_cls=DummyVecEnv if n == 1 else SubprocVecEnv, env_kwargs={"on_unstable": "terminate"})
    rng = np.random.default_rng(0)
    low, high = venv.action_space.low, venv.action_space.high
    try:
        venv.reset()
        for _ in range(3):
            venv.step(rng.uniform(low, high, size=(n, *low.shape)))
        out = []
        blocks = max(1, steps // n)
        for _ in range(repeats):
            acts = rng.uniform(low, high, size=(blocks, n, *low.shape))
            t0 = time.perf_counter()
            for a in acts:
                venv.step(a)
            out.append(blocks * n / (time.perf_counter() - t0))
    finally:
        venv.close()
    return statistics.median(out)


def run(args) -> int:
    try:
        import stable_baselines3  # noqa: F401
    except ImportError:
        raise ConfigError("surgsim bench sb3-vec needs stable-baselines3: pip install 'surgsim_envs[train]'") from None
    import surgsim_envs  # noqa: F401
    from surgsim_envs.envs import TASKS

    if args.task not in TASKS:
        raise ConfigError(f"unknown task {args.task!r}; known: {list(TASKS)}")
    try:
        workers = [int(w) for w in str(args.workers).split(",") if w.strip()]
    except ValueError:
        raise ConfigError(f"--workers must be a comma list of integers >= 1, got {args.workers!r}") from None
    if not workers or min(workers) < 1 or args.steps <= 0 or args.repeats <= 0:
        raise ConfigError("--workers entries, --steps and --repeats must be positive")
    import sys

    from tqdm import tqdm

    rows = []
    for n in tqdm(workers, desc="bench sb3-vec", unit="size", file=sys.stderr):
        r = rate(args.task, n, args.steps, args.repeats)
        rows.append({"workers": n, "vec": "DummyVecEnv" if n == 1 else "SubprocVecEnv", "steps_per_s": r})
        if getattr(args, "shared", False) and n > 1:
            rows.append({"workers": n, "vec": "SB3VectorEnv",
                         "steps_per_s": rate(args.task, n, args.steps, args.repeats, shared=True)})
    base = rows[0]["steps_per_s"]
    for row in rows:
        row["speedup_vs_first"] = row["steps_per_s"] / base
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    if args.json:
        print(json.dumps({"task": args.task, "cpus": os.cpu_count(), "load_1min": load, "rows": rows}, indent=2))
        return 0
    print(f"{args.task}: {os.cpu_count()} CPUs, load average (1 min) {load:.1f}")
    print(f"{'workers':>8s} {'vec env':>14s} {'steps/s':>9s} {'speedup':>8s}")
    for row in rows:
        print(f"{row['workers']:8d} {row['vec']:>14s} {row['steps_per_s']:9.1f} {row['speedup_vs_first']:8.2f}")
    return 0
