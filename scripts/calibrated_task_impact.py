"""Task impact of ``mass_spring_calibrated`` against the default ``mass_spring`` (issue 16 item 3,
"on by default"): reset and env-step wall times of each task (same process, same seeds, random actions).

    python scripts/calibrated_task_impact.py --tasks SurgSim/Palpation-v0,SurgSim/Grasp-v0 --steps 40 --seeds 3
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def main(argv=None) -> int:
    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401  (registers the tasks)

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tasks", default="SurgSim/Palpation-v0,SurgSim/Grasp-v0")
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--models", default="mass_spring,mass_spring_calibrated")
    args = ap.parse_args(argv)
    print(f"load: {os.getloadavg()}")
    for task in args.tasks.split(","):
        for model in args.models.split(","):
            env = gym.make(task, model=model)
            resets, steps = [], []
            for seed in range(args.seeds):
                t0 = time.perf_counter()
                env.reset(seed=seed)
                resets.append(time.perf_counter() - t0)
                env.action_space.seed(seed)
                for _ in range(args.steps):
                    t0 = time.perf_counter()
                    _, _, term, trunc, _ = env.step(env.action_space.sample())
                    steps.append(time.perf_counter() - t0)
                    if term or trunc:
                        break
            t = env.unwrapped.sim.tissue()
            print(f"{task} {model}: integrator {t.active_integrator}, reset median {np.median(resets):.2f} s, "
                  f"env step median {np.median(steps) * 1e3:.1f} ms ({len(steps)} steps)")
            env.close()
    print(f"load: {os.getloadavg()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
