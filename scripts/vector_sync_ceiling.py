"""What a synchronous vector env can reach with 2 workers, from the spread of one task's step times
(docs/benchmarks.md, "Vector envs": the synchronous ceiling).

    python scripts/vector_sync_ceiling.py [TASK ...] [--envs 16] [--rounds 200] [--option KEY=JSON ...]

``--option`` passes a task option to ``gym.make`` (e.g. ``--option replay_approach=false`` for
Slippage's full settle at every reset).

Steps ``--envs`` envs of each task round-robin in this process with random actions (Palpation: never
"report"), timing each step (an autoreset's ``reset`` counted in the step that ends the episode, as a
vector env's worker pays it). For 2 blocks of envs/2 each (2 workers), a synchronous vector step lasts
as long as the slower block: ``efficiency = mean((A + B) / 2) / mean(max(A, B))`` over rounds, and
``2 x efficiency`` is the speed-up over one env that such a vector env reaches with no IPC cost at all.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import gymnasium as gym
import numpy as np

import surgsim_envs  # noqa: F401  (registers the tasks)

TASKS = ("SurgSim/Palpation-v0", "SurgSim/Grasp-v0", "SurgSim/Slippage-v0")


def step_times(task: str, n: int, rounds: int, warmup: int = 20, seed: int = 0, **options) -> np.ndarray:
    """(rounds, n) wall seconds of each env's step (with its reset when the episode ended)."""
    envs = [gym.make(task, **options) for _ in range(n)]
    for i, e in enumerate(envs):
        e.reset(seed=seed + i)
    rng = np.random.default_rng(seed)
    shape = envs[0].action_space.shape
    out = np.zeros((rounds + warmup, n))
    try:
        for r in range(rounds + warmup):
            acts = rng.uniform(-1, 1, (n, *shape)).astype(np.float32)
            if "Palpation" in task:
                acts[:, -1] = -1.0
            for i, e in enumerate(envs):
                t0 = time.perf_counter()
                _, _, te, tr, _ = e.step(acts[i])
                if te or tr:
                    e.reset()
                out[r, i] = time.perf_counter() - t0
    finally:
        for e in envs:
            e.close()
    return out[warmup:]


def sync_efficiency(times: np.ndarray, blocks: int = 2) -> float:
    """Mean block time over mean slowest-block time, envs split into ``blocks`` contiguous blocks."""
    sums = np.stack([b.sum(axis=1) for b in np.array_split(times, blocks, axis=1)])
    return float(sums.mean(axis=0).mean() / sums.max(axis=0).mean())


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("tasks", nargs="*", default=list(TASKS))
    p.add_argument("--envs", type=int, default=16)
    p.add_argument("--rounds", type=int, default=200)
    p.add_argument("--option", action="append", default=[], metavar="KEY=JSON",
                   help="a task option for gym.make, value in JSON (true, 0.5, \"spleen\")")
    a = p.parse_args(argv)
    options = {}
    for item in a.option:
        key, sep, value = item.partition("=")
        try:
            options[key] = json.loads(value)
        except json.JSONDecodeError:
            sep = ""
        if not sep or not key:
            p.error(f"--option {item!r}: write KEY=JSON, e.g. replay_approach=false")
    if a.envs < 2 or a.rounds < 1:
        p.error(f"--envs must be >= 2 and --rounds >= 1, got {a.envs} and {a.rounds}")
    print(f"load average (1 min) {os.getloadavg()[0]:.2f}; {a.envs} envs, 2 blocks, {a.rounds} rounds"
          + (f"; options {options}" if options else ""))
    for task in a.tasks:
        t = step_times(task, a.envs, a.rounds, **options)
        eff = sync_efficiency(t)
        print(f"{task:22s} step median {np.median(t) * 1e6:7.0f} us, p99 {np.percentile(t, 99) * 1e3:6.2f} ms, "
              f"max {t.max() * 1e3:6.1f} ms, std/mean {t.std() / t.mean():.2f}; sync efficiency {eff:.3f} -> "
              f"ceiling x{2 * eff:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
