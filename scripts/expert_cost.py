"""A task's scripted expert against a uniform random policy, per tissue model: success, mean return and
wall time per env step (episode k reset with seed k; the random policy's sampler seeded with k).

    python scripts/expert_cost.py --task SurgSim/Slippage-v0 --models mass_spring,fem_static --seeds 0:10

Prints one line per model and policy. Wall times include each episode's reset (a quasi-static model
factorises its stiffness there); run it twice and keep the warm run (the first compiles numba kernels).
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import surgsim_envs  # noqa: F401  (registers the tasks)
from surgsim_envs.envs.registry import expert


def run(env, make_policy, seeds) -> tuple[float, float, float, int]:
    """(success rate, mean return, seconds per env step, steps) over episodes reset with ``seeds``."""
    wins, returns, steps, t0 = 0, [], 0, time.perf_counter()
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        env.action_space.seed(seed)
        policy = make_policy(env.unwrapped)
        total, done, info = 0.0, False, {}
        while not done:
            obs, r, term, trunc, info = env.step(policy(obs))
            total += float(r)
            steps += 1
            done = term or trunc
        wins += bool(info.get("is_success", info.get("success", False)))
        returns.append(total)
    return wins / len(seeds), float(np.mean(returns)), (time.perf_counter() - t0) / steps, steps


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--task", required=True)
    p.add_argument("--models", default="mass_spring,fem_static", help="comma separated tissue models")
    p.add_argument("--seeds", default="0:10", help="reset seeds START:STOP (stop exclusive)")
    a = p.parse_args(argv)
    start, stop = (int(v) for v in a.seeds.split(":"))
    seeds = range(start, stop)
    make_expert = expert(a.task)
    for model in a.models.split(","):
        env = gym.make(a.task, model=model)
        rand = lambda u, env=env: (lambda obs: env.action_space.sample())  # noqa: E731
        for name, make in (("expert", make_expert), ("random", rand)):
            rate, ret, dt, n = run(env, make, seeds)
            print(f"{a.task} {model:12s} {name:6s} success {rate:4.0%}  return {ret:7.2f}  "
                  f"{dt * 1e3:6.2f} ms / env step ({n} steps)", flush=True)
        env.close()


if __name__ == "__main__":
    main()
