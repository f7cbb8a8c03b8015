"""What one world of a batched ``fem_static`` Palpation-v0 would cost to set up (docs/batch.md, "Not
batched yet"): after a reset draws a new lump, the factorisation of its stiffness and the compliance
columns of every free top-surface node (the surface the probe can reach), on the single env.

    python scripts/fem_static_world_cost.py [--resets 3]
"""
import argparse
import time

import gymnasium as gym
import numpy as np

import surgsim_envs  # noqa: F401  (registers the tasks)

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--resets", type=int, default=3, help="resets (new lumps) to time")
args = parser.parse_args()
env = gym.make("SurgSim/Palpation-v0")
u = env.unwrapped
u.reset(seed=0)
(tissue,) = list(u.sim.tissues.values())
top = np.flatnonzero((tissue.rest_positions[:, 2] > tissue.rest_positions[:, 2].max() - 1e-9) & ~tissue.fixed)
print("nodes", tissue.n_nodes, "free top nodes", len(top), "solver", getattr(tissue, "solver", None))
for seed in range(1, args.resets + 1):
    u.reset(seed=seed)
    t = time.perf_counter()
    tissue.compliance()
    t1 = time.perf_counter() - t
    t = time.perf_counter()
    tissue.precompute(top)
    t2 = time.perf_counter() - t
    print(f"reset {seed}: factorise {t1:.3f} s, {len(top)} surface nodes' columns {t2:.2f} s "
          f"({t2 / len(top) * 1e3:.2f} ms a node); columns {72 * tissue.n_nodes * len(top) / 1e6:.0f} MB, "
          f"surface block {(3 * len(top)) ** 2 * 8 / 1e6:.0f} MB (float64)")
