"""Which closed shells of a surface lie inside another? In about n log n over the shells.

Shells that do not cross (see :mod:`~surgsim_envs.geometry.self_intersection`) are either
disjoint or nested. A shell can lie inside another only when its bounding box does; those pairs
are found by a sweep over the boxes sorted along the mesh's longest axis, and each is decided by
one of its vertices tested against the other shell. Units: those of the mesh.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _box_inside_pairs(lo, hi, order, axis, tol):
    """Pairs (a, b) of boxes with box a inside box b (within ``tol``), a != b."""
    out_a = []
    out_b = []
    n = order.shape[0]
    for k in range(n):
        i = order[k]
        for m in range(k + 1, n):
            j = order[m]
            if lo[j, axis] > hi[i, axis] + tol:
                break
            i_in_j = True
            j_in_i = True
            for d in range(3):
                if lo[i, d] < lo[j, d] - tol or hi[i, d] > hi[j, d] + tol:
                    i_in_j = False
                if lo[j, d] < lo[i, d] - tol or hi[j, d] > hi[i, d] + tol:
                    j_in_i = False
            if i_in_j:
                out_a.append(i)
                out_b.append(j)
            if j_in_i:
                out_a.append(j)
                out_b.append(i)
    return out_a, out_b


def nested_shell(mesh, labels: np.ndarray) -> tuple[int, int] | None:
    """``(inner, outer)`` labels of one shell lying inside another, or None. ``labels`` gives
    each face's shell; the shells must not cross each other."""
    faces = np.asarray(mesh.faces)
    n_shells = int(labels.max()) + 1 if len(labels) else 0
    if n_shells < 2:
        return None
    tri = np.asarray(mesh.triangles, dtype=np.float64)
    lo = np.full((n_shells, 3), np.inf)
    hi = np.full((n_shells, 3), -np.inf)
    np.minimum.at(lo, labels, tri.min(axis=1))
    np.maximum.at(hi, labels, tri.max(axis=1))
    extent = np.ptp(mesh.vertices, axis=0)
    axis = int(np.argmax(extent))
    tol = 1e-9 * float(extent.max())
    order = np.argsort(lo[:, axis], kind="stable")
    inner, outer = _box_inside_pairs(lo, hi, order, axis, tol)
    shells = {}
    for a, b in zip(inner, outer):
        if b not in shells:
            shells[b] = mesh.submesh([np.flatnonzero(labels == b)], append=True)
        point = mesh.vertices[faces[np.flatnonzero(labels == a)[0], 0]]
        if shells[b].contains(point[None, :])[0]:
            return int(a), int(b)
    return None
