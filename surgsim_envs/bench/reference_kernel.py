"""A fixed reference workload, timed beside the env benchmarks, to read their figures on a shared host.

The same env step on this 2-core machine takes 1.4-1.6x longer in some minutes than in others, with
nothing else of ours running (docs/benchmarks.md): the host's own state (clock, a neighbour's load)
moves every timing. This module times a kernel that never changes: the design guide's "minimal
numba spring kernel" (force accumulation + symplectic update), on a 10 x 10 x 10 node lattice of
1 cm with 5,940 springs (the 3 axis neighbours and 4 face diagonals of each node). ``surgsim bench
envs`` times it after every timed run of a task and reports its median (``reference_kernel_us``) and
an env step in units of it (``env_step_in_reference_kernels``): a host that slows both leaves that
figure where it was, a change in our code moves it.

The kernel is real physics (linear springs with dashpots on unit masses, no gravity, explicit
symplectic Euler) so that it cannot be optimised away; tests/test_reference_kernel.py checks its forces
against numpy and that they sum to zero.
"""

from __future__ import annotations

import statistics
import time

import numpy as np
from numba import njit

#: lattice nodes per side, spacing m, spring stiffness N/m, dashpot N s/m, node mass kg, step s
SIDE, SPACING, STIFFNESS, DAMPING, MASS, DT = 10, 0.01, 100.0, 0.05, 1e-3, 1e-4
_OFFSETS = ((1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, 0, 1), (0, 1, 1), (1, -1, 0))


def reference_network(seed: int = 0):
    """``(x (N, 3) m, v (N, 3) m/s, i (S,), j (S,), rest (S,) m)``: the lattice with its nodes moved by
    up to 0.5 mm (so every spring carries a force), at rest."""
    idx = np.arange(SIDE ** 3).reshape(SIDE, SIDE, SIDE)
    grid = np.stack(np.meshgrid(*[np.arange(SIDE)] * 3, indexing="ij"), axis=-1).reshape(-1, 3) * SPACING
    si, sj = [], []
    for dx, dy, dz in _OFFSETS:
        a = idx[max(0, -dx):SIDE - max(0, dx), max(0, -dy):SIDE - max(0, dy), max(0, -dz):SIDE - max(0, dz)]
        b = idx[max(0, dx):SIDE + min(0, dx), max(0, dy):SIDE + min(0, dy), max(0, dz):SIDE + min(0, dz)]
        si.append(a.ravel())
        sj.append(b.ravel())
    si, sj = np.concatenate(si).astype(np.int64), np.concatenate(sj).astype(np.int64)
    rest = np.linalg.norm(grid[sj] - grid[si], axis=1)
    x = grid + np.random.default_rng(seed).uniform(-5e-4, 5e-4, grid.shape)
    return x, np.zeros_like(x), si, sj, rest


@njit(cache=True)
def spring_forces(x, v, si, sj, rest, k, c, f):
    """f (N, 3) N: the springs' and dashpots' forces on the nodes (overwritten)."""
    f[:] = 0.0
    for s in range(si.shape[0]):
        i, j = si[s], sj[s]
        dx = x[j, 0] - x[i, 0]
        dy = x[j, 1] - x[i, 1]
        dz = x[j, 2] - x[i, 2]
        length = np.sqrt(dx * dx + dy * dy + dz * dz)
        ux, uy, uz = dx / length, dy / length, dz / length
        rate = (v[j, 0] - v[i, 0]) * ux + (v[j, 1] - v[i, 1]) * uy + (v[j, 2] - v[i, 2]) * uz
        t = k * (length - rest[s]) + c * rate
        f[i, 0] += t * ux
        f[i, 1] += t * uy
        f[i, 2] += t * uz
        f[j, 0] -= t * ux
        f[j, 1] -= t * uy
        f[j, 2] -= t * uz


@njit(cache=True)
def reference_step(x, v, si, sj, rest, k, c, inv_mass, dt, f):
    """One symplectic Euler step of the network (x, v updated in place)."""
    spring_forces(x, v, si, sj, rest, k, c, f)
    for n in range(x.shape[0]):
        for d in range(3):
            v[n, d] += dt * inv_mass * f[n, d]
            x[n, d] += dt * v[n, d]


def reference_kernel_us(calls: int = 200, repeats: int = 3) -> float:
    """us per :func:`reference_step`: the median over ``repeats`` runs of ``calls`` steps, each run from
    the same initial state (wall time)."""
    x0, v0, si, sj, rest = reference_network()
    f = np.empty_like(x0)
    x, v = x0.copy(), v0.copy()
    reference_step(x, v, si, sj, rest, STIFFNESS, DAMPING, 1.0 / MASS, DT, f)     # compile / load
    out = []
    for _ in range(repeats):
        x[:], v[:] = x0, v0
        t = time.perf_counter()
        for _ in range(calls):
            reference_step(x, v, si, sj, rest, STIFFNESS, DAMPING, 1.0 / MASS, DT, f)
        out.append((time.perf_counter() - t) / calls * 1e6)
    return statistics.median(out)
