"""Median wall time of a one-world reset in a batched task (docs/batch.md, "Resets").

    python scripts/batch_reset_time.py [WORLDS] [--task SurgSim/Palpation-v0] [--device cpu|cuda] [--repeats 15]

After ``reset(seed=0)`` and one step, world 3 (or the last) is reset ``--repeats`` times: the env's whole reset of one world
(the task's ``_reset_worlds``, the hook an autoreset calls: the draws, the lump's Young's factors,
``BatchSimulation.reset_worlds``) and ``BatchSimulation.reset_worlds`` alone; prints their medians
and the load average.
"""

import argparse
import os
import time

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("worlds", nargs="?", type=int, default=256)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--task", default="SurgSim/Palpation-v0")
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args()
    from gymnasium.envs.registration import load_env_creator

    from surgsim_envs.envs import BATCHED

    W = args.worlds
    env = load_env_creator(BATCHED[args.task])(W, device=args.device)
    env.reset(seed=0)
    env.step(np.random.default_rng(0).uniform(-1, 1, (W,) + env.single_action_space.shape))
    one = np.array([3 % W])
    whole, sim_only = [], []
    for _ in range(args.repeats):
        t = time.perf_counter()
        env._reset_worlds(one, {})
        whole.append(time.perf_counter() - t)
        t = time.perf_counter()
        env.sim.reset_worlds(one)
        sim_only.append(time.perf_counter() - t)
    print(f"{args.task}, {W} worlds on {args.device}: the env's reset of one world {np.median(whole) * 1e3:.2f} ms, "
          f"BatchSimulation.reset_worlds {np.median(sim_only) * 1e3:.2f} ms (load {os.getloadavg()[0]:.2f})")


if __name__ == "__main__":
    main()
