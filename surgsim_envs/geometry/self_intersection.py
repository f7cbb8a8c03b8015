"""Does a closed triangle surface cross or touch itself? Counted in numba in about linear time.

Candidate pairs come from a uniform grid hashed into a table (cell size about one triangle):
each triangle is entered in the cells its bounding box covers, and a pair is examined once, in
the cell that holds the lowest corner of the overlap of the two boxes. Two triangles that share
a vertex are neighbours and are not examined. Two that share none *meet* when an edge of one
reaches the closed triangle of the other (through its interior, on its edges or at a corner,
coplanar overlaps included), within ``1e-9`` of the mesh size. In a clean closed surface no two
non-neighbouring triangles meet, so every such pair is a crossing or a touch that makes inside
and outside ambiguous. Units: those of the mesh.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surgsim_envs.errors import ConfigError

#: faces above this are refused (memory of the candidate grid; a surface for a lattice fill needs
#: far fewer: a 5 mm lattice of a 30 cm organ is resolved by ~10^5 faces)
MAX_FACES = 2_000_000
#: bounding-box cells entered per face on average before the grid is coarsened
_MAX_ENTRIES_PER_FACE = 16


@njit(cache=True, inline="always")
def _bary_closed(px, py, pz, ax, ay, az, e1x, e1y, e1z, e2x, e2y, e2z, eps) -> bool:
    """Whether p (in the plane of the triangle a, a + e1, a + e2) lies in the closed triangle."""
    vx, vy, vz = px - ax, py - ay, pz - az
    d00 = e2x * e2x + e2y * e2y + e2z * e2z
    d01 = e2x * e1x + e2y * e1y + e2z * e1z
    d02 = e2x * vx + e2y * vy + e2z * vz
    d11 = e1x * e1x + e1y * e1y + e1z * e1z
    d12 = e1x * vx + e1y * vy + e1z * vz
    den = d00 * d11 - d01 * d01
    if den <= 0.0:
        return False
    u = (d11 * d02 - d01 * d12) / den
    v = (d00 * d12 - d01 * d02) / den
    return u >= -eps and v >= -eps and u + v <= 1.0 + eps


@njit(cache=True, inline="always")
def _segments_meet_2d(p0, p1, q0, q1, tol) -> bool:
    """Closed 2-D segments p0-p1 and q0-q1 meet (within ``tol``)."""
    rx, ry = p1[0] - p0[0], p1[1] - p0[1]
    sx, sy = q1[0] - q0[0], q1[1] - q0[1]
    den = rx * sy - ry * sx
    qpx, qpy = q0[0] - p0[0], q0[1] - p0[1]
    if abs(den) <= tol * (abs(rx) + abs(ry) + abs(sx) + abs(sy) + tol):
        return False  # parallel: an overlap of collinear edges shows as an endpoint inside a triangle
    t = (qpx * sy - qpy * sx) / den
    u = (qpx * ry - qpy * rx) / den
    return -1e-9 <= t <= 1.0 + 1e-9 and -1e-9 <= u <= 1.0 + 1e-9


@njit(cache=True)
def _edge_meets(t1, t2, tol) -> bool:
    """Whether an edge of triangle t1 (3, 3) reaches the closed triangle t2."""
    ax, ay, az = t2[0, 0], t2[0, 1], t2[0, 2]
    e1x, e1y, e1z = t2[1, 0] - ax, t2[1, 1] - ay, t2[1, 2] - az
    e2x, e2y, e2z = t2[2, 0] - ax, t2[2, 1] - ay, t2[2, 2] - az
    nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
    nn = np.sqrt(nx * nx + ny * ny + nz * nz)
    if nn == 0.0:
        return False
    nx, ny, nz = nx / nn, ny / nn, nz / nn
    for k in range(3):
        p, q = t1[k], t1[(k + 1) % 3]
        dp = (p[0] - ax) * nx + (p[1] - ay) * ny + (p[2] - az) * nz
        dq = (q[0] - ax) * nx + (q[1] - ay) * ny + (q[2] - az) * nz
        if (dp > tol and dq > tol) or (dp < -tol and dq < -tol):
            continue
        if abs(dp) <= tol and abs(dq) <= tol:  # the edge lies in the plane: a 2-D test
            if _bary_closed(p[0], p[1], p[2], ax, ay, az, e1x, e1y, e1z, e2x, e2y, e2z, 1e-9) or \
                    _bary_closed(q[0], q[1], q[2], ax, ay, az, e1x, e1y, e1z, e2x, e2y, e2z, 1e-9):
                return True
            # drop the normal's largest axis and test the edge against the three sides
            big = 0
            if abs(ny) > abs(nx):
                big = 1
            if abs(nz) > max(abs(nx), abs(ny)):
                big = 2
            i0, i1 = (1, 2) if big == 0 else ((0, 2) if big == 1 else (0, 1))
            p2 = np.array([p[i0], p[i1]])
            q2 = np.array([q[i0], q[i1]])
            for s in range(3):
                a2 = np.array([t2[s, i0], t2[s, i1]])
                b2 = np.array([t2[(s + 1) % 3, i0], t2[(s + 1) % 3, i1]])
                if _segments_meet_2d(p2, q2, a2, b2, tol):
                    return True
            continue
        s = dp / (dp - dq) if dp != dq else 0.0
        s = min(max(s, 0.0), 1.0)
        cx = p[0] + (q[0] - p[0]) * s
        cy = p[1] + (q[1] - p[1]) * s
        cz = p[2] + (q[2] - p[2]) * s
        if _bary_closed(cx, cy, cz, ax, ay, az, e1x, e1y, e1z, e2x, e2y, e2z, 1e-9):
            return True
    return False


@njit(cache=True, inline="always")
def _hash(ix, iy, iz, mask):
    h = (ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791)
    return h & mask


@njit(cache=True)
def _count_meeting(tri, faces, labels, lo, hi, origin, h, tol):
    """(pairs meeting within one label, pairs meeting across labels)."""
    n = tri.shape[0]
    c0 = np.empty((n, 3), dtype=np.int64)
    c1 = np.empty((n, 3), dtype=np.int64)
    total = 0
    for i in range(n):
        for d in range(3):
            c0[i, d] = int(np.floor((lo[i, d] - tol - origin[d]) / h))
            c1[i, d] = int(np.floor((hi[i, d] + tol - origin[d]) / h))
        total += (c1[i, 0] - c0[i, 0] + 1) * (c1[i, 1] - c0[i, 1] + 1) * (c1[i, 2] - c0[i, 2] + 1)
    size = 1
    while size < 2 * total:
        size *= 2
    mask = size - 1
    start = np.zeros(size + 1, dtype=np.int64)
    for i in range(n):
        for ix in range(c0[i, 0], c1[i, 0] + 1):
            for iy in range(c0[i, 1], c1[i, 1] + 1):
                for iz in range(c0[i, 2], c1[i, 2] + 1):
                    start[_hash(ix, iy, iz, mask) + 1] += 1
    for b in range(size):
        start[b + 1] += start[b]
    fill = start[:-1].copy()
    ent_tri = np.empty(total, dtype=np.int64)
    ent_cell = np.empty((total, 3), dtype=np.int64)
    for i in range(n):
        for ix in range(c0[i, 0], c1[i, 0] + 1):
            for iy in range(c0[i, 1], c1[i, 1] + 1):
                for iz in range(c0[i, 2], c1[i, 2] + 1):
                    b = _hash(ix, iy, iz, mask)
                    k = fill[b]
                    ent_tri[k] = i
                    ent_cell[k, 0], ent_cell[k, 1], ent_cell[k, 2] = ix, iy, iz
                    fill[b] += 1
    same = 0
    across = 0
    for b in range(size):
        for ka in range(start[b], start[b + 1]):
            i = ent_tri[ka]
            for kb in range(ka + 1, start[b + 1]):
                if ent_cell[ka, 0] != ent_cell[kb, 0] or ent_cell[ka, 1] != ent_cell[kb, 1] \
                        or ent_cell[ka, 2] != ent_cell[kb, 2]:
                    continue
                j = ent_tri[kb]
                overlap = True
                owner = True
                for d in range(3):
                    a_lo = max(lo[i, d], lo[j, d])
                    if a_lo > min(hi[i, d], hi[j, d]) + 2.0 * tol:
                        overlap = False
                        break
                    if max(c0[i, d], c0[j, d]) != ent_cell[ka, d]:
                        owner = False  # examined in the cell of the overlap's lowest corner
                if not overlap or not owner:
                    continue
                adjacent = False
                for a in range(3):
                    for c in range(3):
                        if faces[i, a] == faces[j, c]:
                            adjacent = True
                if adjacent:
                    continue
                if _edge_meets(tri[i], tri[j], tol) or _edge_meets(tri[j], tri[i], tol):
                    if labels[i] == labels[j]:
                        same += 1
                    else:
                        across += 1
    return same, across


def meeting_pairs(mesh, labels=None) -> tuple[int, int]:
    """Pairs of non-neighbouring triangles of ``mesh`` (a trimesh.Trimesh) that meet, as
    ``(within one label, across labels)``; ``labels`` (one int per face, e.g. the shell) defaults
    to one label for all. Raises ConfigError above :data:`MAX_FACES` faces."""
    tri = np.ascontiguousarray(mesh.triangles, dtype=np.float64)
    n = len(tri)
    if n > MAX_FACES:
        raise ConfigError(f"surface has {n:,} faces; at most {MAX_FACES:,} are checked. Decimate it (e.g. "
                          "trimesh's simplify_quadric_decimation or MeshLab) to the lattice resolution")
    if n < 2:
        return 0, 0
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    labels = np.zeros(n, dtype=np.int64) if labels is None else np.ascontiguousarray(labels, dtype=np.int64)
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    extent = float(np.ptp(mesh.vertices, axis=0).max())
    tol = 1e-9 * extent
    size = hi - lo
    h = max(float(np.median(size.max(axis=1))), 1e-6 * extent, 1e-300)
    cells = np.floor((hi + tol) / h) - np.floor((lo - tol) / h) + 1
    while float(np.prod(cells, axis=1).sum()) > _MAX_ENTRIES_PER_FACE * n:
        h *= 2.0  # a few huge triangles would enter too many cells: coarsen
        cells = np.floor((hi + tol) / h) - np.floor((lo - tol) / h) + 1
    origin = lo.min(axis=0)
    same, across = _count_meeting(tri, faces, labels, lo, hi, origin, h, tol)
    return int(same), int(across)


def self_intersections(mesh) -> int:
    """Number of pairs of non-neighbouring triangles of ``mesh`` that cross or touch; 0 for a
    clean closed surface."""
    same, across = meeting_pairs(mesh)
    return same + across
