"""Does a closed triangle surface cross itself? Counted in numba: a sweep over the triangles'
bounding boxes sorted along x gives candidate pairs of non-adjacent triangles, and a pair counts
when an edge of one passes through the interior of the other (strict barycentric test, so
triangles that only touch at a shared vertex or edge do not count). Units: those of the mesh."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _edge_through(t1, t2, tol) -> bool:
    """Whether an edge of triangle t1 (3, 3) passes through the interior of triangle t2."""
    ax, ay, az = t2[0, 0], t2[0, 1], t2[0, 2]
    e1x, e1y, e1z = t2[1, 0] - ax, t2[1, 1] - ay, t2[1, 2] - az     # b - a
    e2x, e2y, e2z = t2[2, 0] - ax, t2[2, 1] - ay, t2[2, 2] - az     # c - a
    nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
    nn = np.sqrt(nx * nx + ny * ny + nz * nz)
    if nn == 0.0:
        return False
    nx, ny, nz = nx / nn, ny / nn, nz / nn
    for k in range(3):
        p, q = t1[k], t1[(k + 1) % 3]
        dp = (p[0] - ax) * nx + (p[1] - ay) * ny + (p[2] - az) * nz
        dq = (q[0] - ax) * nx + (q[1] - ay) * ny + (q[2] - az) * nz
        if (dp > tol and dq > tol) or (dp < -tol and dq < -tol) or abs(dp - dq) <= tol:
            continue
        s = dp / (dp - dq)
        v2x = p[0] + (q[0] - p[0]) * s - ax
        v2y = p[1] + (q[1] - p[1]) * s - ay
        v2z = p[2] + (q[2] - p[2]) * s - az
        # barycentric coordinates of the crossing point in (v0 = c - a, v1 = b - a)
        d00 = e2x * e2x + e2y * e2y + e2z * e2z
        d01 = e2x * e1x + e2y * e1y + e2z * e1z
        d02 = e2x * v2x + e2y * v2y + e2z * v2z
        d11 = e1x * e1x + e1y * e1y + e1z * e1z
        d12 = e1x * v2x + e1y * v2y + e1z * v2z
        den = d00 * d11 - d01 * d01
        if den == 0.0:
            continue
        u = (d11 * d02 - d01 * d12) / den
        v = (d00 * d12 - d01 * d02) / den
        if u > 1e-9 and v > 1e-9 and u + v < 1.0 - 1e-9:
            return True
    return False


@njit(cache=True)
def _count_crossings(tri, faces, order, lo, hi, tol) -> int:
    count = 0
    n = order.shape[0]
    for k in range(n):
        i = order[k]
        for m in range(k + 1, n):
            j = order[m]
            if lo[j, 0] > hi[i, 0] + tol:
                break
            if not (lo[i, 1] <= hi[j, 1] + tol and lo[j, 1] <= hi[i, 1] + tol
                    and lo[i, 2] <= hi[j, 2] + tol and lo[j, 2] <= hi[i, 2] + tol
                    and lo[i, 0] <= hi[j, 0] + tol):
                continue
            adjacent = False
            for a in range(3):
                for b in range(3):
                    if faces[i, a] == faces[j, b]:
                        adjacent = True
            if adjacent:
                continue
            if _edge_through(tri[i], tri[j], tol) or _edge_through(tri[j], tri[i], tol):
                count += 1
    return count


def self_intersections(mesh, max_faces: int = 20_000) -> int:
    """Number of pairs of non-adjacent triangles of ``mesh`` (a trimesh.Trimesh) that cross; 0
    for a clean surface. Skipped (0) above ``max_faces``."""
    tri = np.ascontiguousarray(mesh.triangles, dtype=np.float64)
    if len(tri) > max_faces or len(tri) == 0:
        return 0
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    tol = 1e-9 * float(np.ptp(mesh.vertices, axis=0).max())
    order = np.argsort(lo[:, 0], kind="stable")
    return int(_count_crossings(tri, faces, order, lo, hi, tol))
