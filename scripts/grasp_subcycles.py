"""Grasp-v0 env-step CPU time and failures against ``tissue_subcycles`` (docs/benchmarks.md,
"Grasp-v0: why 0.4 ms, and tissue sub-cycles"). Same process, the same random actions from seeds 0..repeats-1
for every setting; thread CPU time (steadier than wall time on a shared machine).

    MUJOCO_GL=egl python scripts/grasp_subcycles.py [--subcycles 1,2,5] [--steps 100] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import time

import gymnasium as gym
import mujoco
import numpy as np

import surgsim_envs  # noqa: F401
from surgsim_envs.errors import TissueUnstableError


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--subcycles", default="1,2,5")
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args()
    ns = [int(v) for v in args.subcycles.split(",")]
    envs = {n: gym.make("SurgSim/Grasp-v0", tissue_subcycles=n) for n in ns}
    acts = np.random.default_rng(0).uniform(-1, 1, (args.steps, 4)).astype(np.float32)
    cpu = {n: [] for n in ns}
    qacc = {n: 0 for n in ns}
    diverged = {n: 0 for n in ns}
    for r in range(args.repeats):
        for n, env in envs.items():
            env.reset(seed=r)
            t0 = time.thread_time()
            for a in acts:
                try:
                    _, _, term, trunc, _ = env.step(a)
                except TissueUnstableError:
                    diverged[n] += 1
                    env.reset()
                    continue
                qacc[n] += int(env.unwrapped.sim.data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number)
                if term or trunc:
                    env.reset()
            cpu[n].append((time.thread_time() - t0) / len(acts) * 1e6)
    print(f"load average {os.getloadavg()[0]:.1f}")
    for n in ns:
        print(f"tissue_subcycles={n}: env step CPU {np.median(cpu[n]):.0f} us, MuJoCo bad-QACC warnings {qacc[n]}, "
              f"tissue divergences {diverged[n]}")


if __name__ == "__main__":
    main()
