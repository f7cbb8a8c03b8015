"""Task impact of ``mass_spring_calibrated`` against ``mass_spring`` (should it be the tasks' default?): reset
and env-step wall times of each task (same process, same seeds, random actions, the models run in
turn per seed so that the machine load hits both alike), the integrator each step took, and a
stability soak (``--soak``: that many random env steps per task and model, resets on episode end,
counting TissueUnstableError).

    python scripts/calibrated_task_impact.py --tasks SurgSim/Palpation-v0,SurgSim/Grasp-v0,SurgSim/Slippage-v0 \\
        --steps 60 --seeds 3
    python scripts/calibrated_task_impact.py --generic      # both models on the generic loop
    python scripts/calibrated_task_impact.py --tasks SurgSim/Grasp-v0 --models mass_spring_calibrated --soak 10000
"""

from __future__ import annotations

import argparse
import collections
import os
import time

import numpy as np


GENERIC = False    # --generic: every Simulation steps with the generic (per-substep Python) loop


def _make(task: str, model: str):
    import gymnasium as gym

    return gym.make(task, model=model)


def _reset(env, seed: int) -> None:
    env.reset(seed=seed)
    if GENERIC:       # a task may build a Simulation per organ on reset: switch them all
        u = env.unwrapped
        for sim in [u.sim, *getattr(u, "_sims", {}).values()]:
            sim.compiled_substeps = False


def timing(task: str, models: list[str], steps: int, seeds: int) -> None:
    """Per model: median reset (s) and env step (ms), env steps/s, integrators used."""
    envs = {m: _make(task, m) for m in models}
    resets = {m: [] for m in models}
    times = {m: [] for m in models}
    used = {m: collections.Counter() for m in models}
    for seed in range(seeds):
        for m, env in envs.items():
            t0 = time.perf_counter()
            _reset(env, seed)
            resets[m].append(time.perf_counter() - t0)
            env.action_space.seed(seed)
            for _ in range(steps):
                a = env.action_space.sample()
                t0 = time.perf_counter()
                _, _, term, trunc, _ = env.step(a)
                times[m].append(time.perf_counter() - t0)
                used[m][env.unwrapped.sim.tissue().active_integrator] += 1
                if term or trunc:
                    break
    base = float(np.median(times[models[0]]))
    for m in models:
        med = float(np.median(times[m]))
        print(f"{task} {m}: reset median {np.median(resets[m]):.3f} s, env step median {med * 1e3:.2f} ms "
              f"({1.0 / med:.0f} steps/s, {med / base:.2f}x {models[0]}), {len(times[m])} steps, "
              f"integrators {dict(used[m])}", flush=True)
    for env in envs.values():
        env.close()


def soak(task: str, model: str, steps: int) -> None:
    """``steps`` random env steps (reset on episode end, seeds 0, 1, ...): TissueUnstableErrors counted."""
    from tqdm import tqdm

    from surgsim_envs.errors import TissueUnstableError

    env = _make(task, model)
    seed, unstable, episodes = 0, 0, 1
    _reset(env, seed)
    env.action_space.seed(seed)
    used = collections.Counter()
    t0 = time.perf_counter()
    for _ in tqdm(range(steps), desc=f"soak {task} {model}", mininterval=5.0):
        try:
            _, _, term, trunc, info = env.step(env.action_space.sample())
        except TissueUnstableError as err:
            unstable += 1
            print(f"  unstable (seed {seed}): {err}", flush=True)
            term = True
        used[env.unwrapped.sim.tissue().active_integrator] += 1
        if term or trunc:
            seed += 1
            episodes += 1
            _reset(env, seed)
            env.action_space.seed(seed)
    wall = time.perf_counter() - t0
    print(f"soak {task} {model}: {steps} steps, {episodes} episodes, {unstable} TissueUnstableError, "
          f"{steps / wall:.0f} steps/s, integrators {dict(used)}", flush=True)
    env.close()


def main(argv=None) -> int:
    import surgsim_envs.envs  # noqa: F401  (registers the tasks)

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tasks", default="SurgSim/Palpation-v0,SurgSim/Grasp-v0,SurgSim/Slippage-v0")
    ap.add_argument("--steps", type=int, default=60, help="timed random env steps per seed")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--models", default="mass_spring,mass_spring_calibrated")
    ap.add_argument("--soak", type=int, default=0, help="instead of timing: random env steps per task and model")
    ap.add_argument("--generic", action="store_true",
                    help="every model on the generic per-substep loop (Simulation.compiled_substeps = False)")
    args = ap.parse_args(argv)
    global GENERIC
    GENERIC = args.generic
    models = args.models.split(",")
    print(f"load: {os.getloadavg()}", flush=True)
    for task in args.tasks.split(","):
        if args.soak:
            for m in models:
                soak(task, m, args.soak)
        else:
            timing(task, models, args.steps, args.seeds)
    print(f"load: {os.getloadavg()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
