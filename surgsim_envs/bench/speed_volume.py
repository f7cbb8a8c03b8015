"""The benchmark volumes of ``surgsim bench speed`` and its relatives: a box on a 5 mm lattice of a
given node count, and the load pressed on its top."""

from __future__ import annotations

import math

import numpy as np

SPACING = 0.005  # m


def lattice_counts(target: int) -> tuple[int, int, int]:
    """Nodes per axis (a, a, b) with b <= a and a*a*b closest to ``target`` (ties: most cube-like)."""
    best = None
    for a in range(2, int(math.isqrt(target)) + 2):
        b = max(2, min(a, round(target / (a * a))))
        key = (abs(a * a * b - target), a - b)
        if best is None or key < best[0]:
            best = (key, (a, a, b))
    return best[1]


def bench_volume(target: int):
    """A box volume on a 5 mm lattice with about ``target`` nodes."""
    from surgsim_envs.geometry import box_volume

    counts = np.array(lattice_counts(target))
    return box_volume(tuple((counts - 1) * SPACING), SPACING, name=f"bench{target}")


def top_load(model, top: np.ndarray) -> np.ndarray:
    """(N, 3) N: 0.5 N down, shared by the ``top`` nodes."""
    forces = np.zeros((model.n_nodes, 3))
    forces[top, 2] = -0.5 / max(int(top.sum()), 1)
    return forces
