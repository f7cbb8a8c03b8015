"""Is an env step slower in a child process, and what do two processes give on the 2 cores?
(CHANGELOG.md, "Re-measured on a quiet machine (16:50 UTC)").

    python scripts/worker_step_check.py [TASK] [--steps N] [--rounds R]

``child``: the same fixed random actions stepped in this process, a forked and a spawned child
(thread CPU per step). ``pair``: one process alone, then two independent processes at once (no IPC):
their summed rate over the lone rate is the ceiling any vector env could reach here.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import time

import gymnasium as gym
import numpy as np

import surgsim_envs  # noqa: F401  (registers the tasks)


def _run(task: str, steps: int, queue=None) -> tuple[float, float]:
    """(thread CPU us per step, wall steps/s) over ``steps`` fixed random actions after 200 warm-up."""
    env = gym.make(task)
    env.reset(seed=0)
    acts = np.random.default_rng(0).uniform(-1, 1, (steps + 200, *env.action_space.shape)).astype(np.float32)
    for k in range(steps + 200):
        if k == 200:
            c0, w0 = time.thread_time(), time.perf_counter()
        _, _, te, tr, _ = env.step(acts[k])
        if te or tr:
            env.reset()
    out = ((time.thread_time() - c0) / steps * 1e6, steps / (time.perf_counter() - w0))
    env.close()
    if queue is not None:
        queue.put(out)
    return out


def _in_child(method: str, task: str, steps: int, n: int = 1) -> list:
    ctx = mp.get_context(method)
    q = ctx.Queue()
    procs = [ctx.Process(target=_run, args=(task, steps, q)) for _ in range(n)]
    for p in procs:
        p.start()
    res = [q.get() for _ in procs]
    for p in procs:
        p.join()
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("task", nargs="?", default="SurgSim/Palpation-v0")
    ap.add_argument("--steps", type=int, default=1200)
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args()
    for r in range(a.rounds):
        here = _run(a.task, a.steps)[0]
        fork = _in_child("fork", a.task, a.steps)[0][0]
        spawn = _in_child("spawn", a.task, a.steps)[0][0]
        alone = _in_child("fork", a.task, a.steps)[0][1]
        pair = sum(x[1] for x in _in_child("fork", a.task, a.steps, n=2))
        with open("/proc/loadavg") as f:
            load = f.read().split()[0]
        print(f"round {r + 1}: us/step here {here:.0f}, forked {fork:.0f}, spawned {spawn:.0f}; "
              f"steps/s alone {alone:.0f}, two at once {pair:.0f} ({pair / alone:.2f}x); load {load}")


if __name__ == "__main__":
    main()
