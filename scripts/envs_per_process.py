"""What stepping many envs round-robin in one process costs per step, against stepping fewer
(docs/benchmarks.md, "Vector envs"): each env's arrays are evicted from the core's
cache by the others' steps, so a process with many envs steps each more slowly than one env.

    python scripts/envs_per_process.py [TASK] [--envs 1,4,8,16,32,64] [--rounds 12] [--steps 128]

Makes max(--envs) envs of TASK, then in each round times --steps env steps for every count k in
--envs (env j % k for step j, random actions; Palpation: "report" held at -1), by thread CPU time,
alternating the counts within the round so the host's state is shared. Prints per count the median
us per step and the median over rounds of its ratio to the first count's. Run two copies at once to
have the other core busy too, as in a vector env with 2 workers.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import surgsim_envs  # noqa: F401  (registers the tasks)
from surgsim_envs.bench.random_actions import random_actions


def per_step_us(task: str, counts, rounds: int, steps: int, seed: int = 0) -> dict:
    """count -> (median us per env step, median ratio to the first count's in the same round)."""
    envs = [gym.make(task) for _ in range(max(counts))]
    try:
        for i, e in enumerate(envs):
            e.reset(seed=seed + i)
        rng = np.random.default_rng(seed)
        space = envs[0].action_space
        times = {k: [] for k in counts}
        for _ in range(rounds + 1):                      # the first round warms up
            for k in counts:
                acts = random_actions(space, steps, rng, "Palpation" in task)
                t0 = time.thread_time()
                for j in range(steps):
                    e = envs[j % k]
                    _, _, te, tr, _ = e.step(acts[j])
                    if te or tr:
                        e.reset()
                times[k].append((time.thread_time() - t0) / steps * 1e6)
    finally:
        for e in envs:
            e.close()
    base = np.array(times[counts[0]][1:])
    return {k: (float(np.median(v[1:])), float(np.median(np.array(v[1:]) / base))) for k, v in times.items()}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("task", nargs="?", default="SurgSim/Palpation-v0")
    p.add_argument("--envs", default="1,4,8,16,32,64", help="env counts, comma-separated (default 1,4,8,16,32,64)")
    p.add_argument("--rounds", type=int, default=12, help="timed rounds (default 12)")
    p.add_argument("--steps", type=int, default=128, help="env steps per count per round (default 128)")
    a = p.parse_args()
    try:
        counts = [int(c) for c in a.envs.split(",")]
    except ValueError:
        raise SystemExit(f"--envs takes env counts (integers), comma-separated, e.g. 1,4,16; got {a.envs!r}") from None
    if not counts or min(counts) < 1 or a.rounds < 1 or a.steps < 1:
        raise SystemExit(f"--envs needs counts >= 1 and --rounds/--steps >= 1, got {a.envs!r}, {a.rounds}, {a.steps}")
    res = per_step_us(a.task, counts, a.rounds, a.steps)
    print(f"{a.task}: us per env step (thread CPU) with k envs round-robin; ratio to {counts[0]} env(s)")
    for k, (us, ratio) in res.items():
        print(f"  {k:4d} envs  {us:8.1f} us  {ratio:6.3f}")


if __name__ == "__main__":
    main()
