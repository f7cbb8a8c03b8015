"""``surgsim warmup``: build the numba caches ahead, for the demo and every task's default model.

The first process on a checkout compiles the physics kernels (numba, ``cache=True``): tens of
seconds on two cores, after which every run loads them from ``__pycache__``. This command does it
up front under a progress bar that names the stage and the kernel being compiled:

* ``demo: palpation scene`` / ``demo: grasp scene``: the demo's schedule, shortened
  (:func:`surgsim_envs.scene.demo.warmup_stages`); ``surgsim demo`` runs these itself when they
  are cold;
* ``task: <id>``: every registered task with its default config, reset with seed 0 and stepped
  with a few actions (the action space's low, middle and high corners).

A stage whose kernels are already cached only loads them (a second or two). ``--force``
recompiles everything (the caches are cleared first); ``--list`` prints the stages; ``--json``
prints per stage its wall seconds and the number of kernels compiled.
"""

from __future__ import annotations

import argparse
import json
import sys

#: steps per task stage (the actions cycle low, middle, high)
TASK_STEPS = 3


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--only", default=None,
                        help="comma-separated stage names or prefixes, e.g. 'demo' or 'task: SurgSim/Grasp-v0'")
    parser.add_argument("--force", action="store_true", help="clear the package's numba caches first, compile all")
    parser.add_argument("--list", action="store_true", help="print the stages and whether each is warm; run nothing")
    parser.add_argument("--json", action="store_true", help="print per stage {name, seconds, kernels_compiled}")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def task_stage(env_id: str):
    """Stage ``task: <env_id>``: make the task, reset (seed 0), step its corner actions, close."""
    from surgsim_envs.scene.kernel_warmup import Stage

    def run():
        import gymnasium as gym
        import numpy as np

        env = gym.make(env_id)
        try:
            env.reset(seed=0)
            low, high = env.action_space.low, env.action_space.high
            corners = (low, 0.5 * (low + high), high)
            for k in range(TASK_STEPS):
                _, _, term, trunc, _ = env.step(np.asarray(corners[k % 3], dtype=env.action_space.dtype))
                if term or trunc:
                    env.reset(seed=k + 1)
        finally:
            env.close()

    return Stage(f"task: {env_id}", run)


def all_stages() -> list:
    from surgsim_envs.envs import QUASI_STATIC_TASKS, TASKS, register_envs
    from surgsim_envs.scene.demo import warmup_stages

    register_envs()
    return warmup_stages() + [task_stage(env_id) for env_id in {**TASKS, **QUASI_STATIC_TASKS}]


def select(stages: list, only: str | None) -> list:
    """The stages whose name starts with one of the comma-separated ``only`` prefixes."""
    if not only:
        return stages
    from surgsim_envs.errors import ConfigError

    wanted = [w.strip() for w in only.split(",") if w.strip()]
    chosen = [s for s in stages if any(s.name.startswith(w) for w in wanted)]
    unknown = [w for w in wanted if not any(s.name.startswith(w) for s in stages)]
    if unknown or not chosen:
        raise ConfigError(f"--only {only!r}: no stage starts with {unknown or wanted}; stages: "
                          f"{[s.name for s in stages]}")
    return chosen


def run(args) -> int:
    from surgsim_envs.numba_cache import PACKAGE, caches_here, clear_caches, is_warm
    from surgsim_envs.scene.kernel_warmup import run_stages

    stages = select(all_stages(), args.only)
    if args.list:
        for s in stages:
            state = {True: "warm", False: "cold", None: "unknown (caches outside the package)"}[is_warm(s.name)]
            print(f"{s.name:<40} {state}")
        return 0
    if args.force:
        print(f"surgsim warmup: cleared {clear_caches()} numba cache files under {PACKAGE}", file=sys.stderr)
    if not caches_here():
        print("surgsim warmup: note: numba keeps the caches outside the package (NUMBA_CACHE_DIR or a read-only "
              "install); they are built there", file=sys.stderr)     # stdout stays the table or the JSON
    results = run_stages(stages, desc="surgsim warmup", progress=not args.quiet)
    if args.json:
        print(json.dumps([{"name": r.name, "seconds": round(r.seconds, 3), "kernels_compiled": r.kernels_compiled}
                          for r in results], indent=2))
        return 0
    total = sum(r.seconds for r in results)
    kernels = sum(r.kernels_compiled for r in results)
    for r in results:
        print(f"  {r.name:<40} {r.seconds:6.1f} s  {r.kernels_compiled:4d} kernels compiled")
    print(f"surgsim warmup: {len(results)} stages in {total:.1f} s, {kernels} kernels compiled"
          + ("" if kernels else " (all were cached)"))
    return 0
