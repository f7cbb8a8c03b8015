"""LayeredPalpation-v0's env step with its default wall (``fem_hex``) against the paper's springs
(``model="layered"``), alternated in one process: random actions with their resets, median of the
repeats, the 1-minute load beside each run.

    python scripts/layered_default_cost.py                 # random actions: commits end most episodes in 1-3 presses
    python scripts/layered_default_cost.py --no-commit     # 30 presses an episode (the commit action held off)
"""
import argparse
import os
import time

import gymnasium as gym
import numpy as np

import surgsim_envs  # noqa: F401

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--steps", type=int, default=300)
parser.add_argument("--repeats", type=int, default=3)
parser.add_argument("--no-commit", action="store_true", help="hold the commit action off (full 30-press episodes)")
args = parser.parse_args()
times: dict[str, list[float]] = {}
for rep in range(args.repeats):
    for model in ("fem_hex", "layered"):
        env = gym.make("SurgSim/LayeredPalpation-v0", model=model)
        env.reset(seed=rep)
        env.action_space.seed(rep)
        for _ in range(20):                                  # warm-up: kernels, first factorisation
            a = env.action_space.sample()
            a[3] = -1.0
            env.step(a)
        env.reset(seed=rep)
        resets, t = 0, time.perf_counter()
        for _ in range(args.steps):
            a = env.action_space.sample()
            if args.no_commit:
                a[3] = -1.0
            _, _, term, trunc, _ = env.step(a)
            if term or trunc:
                env.reset()
                resets += 1
        dt = (time.perf_counter() - t) / args.steps
        times.setdefault(model, []).append(dt)
        print(f"run {rep} {model}: {1e3 * dt:.2f} ms an env step, {resets} resets in {args.steps} steps, "
              f"load {os.getloadavg()[0]:.1f}", flush=True)
        env.close()
med = {k: float(np.median(v)) for k, v in times.items()}
print(f"median: fem_hex {1e3 * med['fem_hex']:.2f} ms, layered {1e3 * med['layered']:.2f} ms, "
      f"ratio {med['fem_hex'] / med['layered']:.2f}")
