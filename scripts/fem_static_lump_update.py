"""A lump as a low-rank update of one shared compliance (docs/batch.md, "Not batched yet").

Palpation-v0's reset draws a lump that stiffens the tets near it: K = K0 + dK, where K0 is the slab
without the lump and dK is non-zero only on the r free dofs S of the nodes the lump's tets (and
their averaged nodal pressure) touch. With C0 = K0^-1 on the free dofs (shared by every world that
draws the same Young's scale; another scale s divides it by s), Woodbury gives the lumpy body's
compliance columns without factorising K:

    C[:, A] = C0[:, A] - C0[:, S] D M^-1 C0[S, A],   D = dK[S, S],   M = I + C0[S, S] D

(M is r x r, its eigenvalues >= 1: D and C0 are positive semi-definite). This script builds
Palpation-v0's default slab, its dense C0 once, and for each reset compares the columns of every free
top-surface node (the surface the probe can reach) with back-substitutions of the lumpy stiffness's
own factorisation, and times both.

    python scripts/fem_static_lump_update.py [--resets 3]
"""
import argparse
import time

import gymnasium as gym
import numpy as np
import scipy.sparse.linalg as spla

import surgsim_envs  # noqa: F401  (registers the tasks)
from surgsim_envs.tissue.lump_update import LumpCompliance, dense_compliance, stiffness_change

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--resets", type=int, default=3, help="resets (new lumps) to compare")
args = parser.parse_args()

env = gym.make("SurgSim/Palpation-v0")
env.reset(seed=0)
(tissue,) = list(env.unwrapped.sim.tissues.values())
fdofs = np.flatnonzero(np.repeat(~tissue.fixed, 3))
top = np.flatnonzero((tissue.rest_positions[:, 2] > tissue.rest_positions[:, 2].max() - 1e-9) & ~tissue.fixed)
pos = np.full(3 * tissue.n_nodes, -1)
pos[fdofs] = np.arange(len(fdofs))
a_cols = pos[(3 * top[:, None] + np.arange(3)).ravel()]          # the surface nodes' free dofs
print(f"nodes {tissue.n_nodes}, free dofs {len(fdofs)}, free top-surface nodes {len(top)} ({len(a_cols)} columns)")


def free_stiffness():
    return tissue.stiffness_matrix().tocsc()[fdofs][:, fdofs].tocsc()


tissue.scale_material("young", 1.0)                              # the slab as built: no lump, scale 1
k_unit = free_stiffness()
t = time.perf_counter()
c0_unit = dense_compliance(k_unit)
print(f"dense C0 of the lump-free slab: {time.perf_counter() - t:.1f} s, {c0_unit.nbytes / 1e6:.0f} MB (float64), "
      "shared by every world")

for seed in range(1, args.resets + 1):
    env.reset(seed=seed)
    scale = env.unwrapped.inclusion["young_scale"]
    k_lump = free_stiffness()
    t = time.perf_counter()                                      # the Woodbury route
    world = LumpCompliance(c0_unit, stiffness_change(k_lump, k_unit, scale), scale)
    cols = world.columns(a_cols)
    t_wood = time.perf_counter() - t
    t = time.perf_counter()                                      # the direct route
    lu_k = spla.splu(k_lump, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
    t_fact = time.perf_counter() - t
    rhs = np.zeros((len(fdofs), len(a_cols)))
    rhs[a_cols, np.arange(len(a_cols))] = 1.0
    t = time.perf_counter()
    direct = lu_k.solve(rhs)
    t_cols = time.perf_counter() - t
    err = np.max(np.abs(cols - direct)) / np.max(np.abs(direct))
    r = len(world.support)
    print(f"reset {seed} (Young's scale {scale:.3f}): support r = {r} dofs; Woodbury {t_wood:.2f} s (M {r}x{r}), "
          f"direct factorise {t_fact:.2f} s + {len(a_cols)} columns {t_cols:.2f} s; largest difference {err:.1e} of "
          f"the largest compliance; {world.nbytes / 1e6:.2f} MB per world beyond the shared C0")
env.close()
