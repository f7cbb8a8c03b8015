"""Tool shapes: kind codes and numba signed-distance / closest-point kernels (no MuJoCo import).

Shapes follow MuJoCo's ``geom_size`` convention and are posed in the world frame exactly as MuJoCo
reports them: centre ``pos`` (3,) = ``d.geom_xpos[g]`` and rotation ``mat`` (9,) = ``d.geom_xmat[g]``,
row-major, mapping local to world coordinates (``x_world = pos + R @ x_local``).

===========  ====  ============================================  ==========================
kind         code  size (m)                                      bounding-sphere radius
===========  ====  ============================================  ==========================
SPHERE       0     (r, -, -)                                     r
CAPSULE      1     (r, half_length, -), axis = local z           r + half_length
BOX          2     (hx, hy, hz) half extents                      |(hx, hy, hz)|
CYLINDER     3     (r, half_length, -), axis = local z           sqrt(r^2 + half_length^2)
ROUNDED_BOX  4     (hx, hy, hz); edges rounded, r = min of them   |(hx, hy, hz)|
===========  ====  ============================================  ==========================

A rounded box is the box of the same size with every edge and corner rounded to the radius of its
thinnest half extent (a 3 mm thick grasper jaw gets 1.5 mm round edges: its cross-section is a
stadium): the points within that radius of the inner box of half extents ``h - r``. MuJoCo has no
such geom; a tool declares which of its box geoms the tissue contact treats as rounded
(``ToolSpec.rounded_geoms``; the grasper's ``jaw_edges="round"``). A flat box edge presses into
tissue like the edge of a flat punch, where the contact pressure is singular and the force depends
on how the lattice's contact points meet the edge; a rounded edge has a finite curvature.

Signed distance ``d`` (m) is negative inside the shape; the normal is the unit outward normal of
the shape at the closest surface point (it points from the shape towards the query point when the
point is outside, and towards the nearest face when inside); ``closest`` is that surface point.
Where the normal is not unique (the centre of a sphere, the axis of a capsule) a fixed valid
direction is returned.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from surgsim_envs.errors import ConfigError

SPHERE, CAPSULE, BOX, CYLINDER, ROUNDED_BOX = 0, 1, 2, 3, 4
SHAPE_NAMES = {SPHERE: "sphere", CAPSULE: "capsule", BOX: "box", CYLINDER: "cylinder", ROUNDED_BOX: "rounded box"}
N_KINDS = 5


@njit(cache=True, inline="always")
def bounding_radius(kind, s0, s1, s2):
    """Radius (m) of a sphere about the shape centre that contains the whole shape of size
    (s0, s1, s2) (-1 for a bad kind)."""
    if kind == SPHERE:
        return s0
    if kind == CAPSULE:
        return s0 + s1
    if kind == BOX or kind == ROUNDED_BOX:
        return math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    if kind == CYLINDER:
        return math.sqrt(s0 * s0 + s1 * s1)
    return -1.0


@njit(cache=True, inline="always")
def local_outside(kind, s0, s1, s2, qx, qy, qz):
    """Cheap exact test that local point (qx, qy, qz) is outside (or on) the shape: no square roots."""
    if kind == BOX or kind == ROUNDED_BOX:       # a rounded box lies inside its box
        return abs(qx) >= s0 or abs(qy) >= s1 or abs(qz) >= s2
    if kind == SPHERE:
        return qx * qx + qy * qy + qz * qz >= s0 * s0
    if kind == CYLINDER:
        return abs(qz) >= s1 or qx * qx + qy * qy >= s0 * s0
    if kind == CAPSULE:
        sz = min(max(qz, -s1), s1)
        return qx * qx + qy * qy + (qz - sz) * (qz - sz) >= s0 * s0
    return True


@njit(cache=True, inline="always")
def _box_sdf(s0, s1, s2, r, qx, qy, qz, n_out, c_out):
    """Signed distance (m) of local point q to the box of half extents (s0, s1, s2) with its edges
    and corners rounded to ``r`` (0: the plain box; at most min(s0, s1, s2)): the distance to the
    inner box of half extents (s - r) minus r, its normal, and the closest point moved out by r along
    it. With r = min(s) the inner box is flat along the thinnest axis; a point exactly on it takes
    that axis as its normal."""
    hx, hy, hz = s0 - r, s1 - r, s2 - r
    ax, ay, az = abs(qx) - hx, abs(qy) - hy, abs(qz) - hz
    if ax > 0.0 or ay > 0.0 or az > 0.0:
        cx = min(max(qx, -hx), hx)
        cy = min(max(qy, -hy), hy)
        cz = min(max(qz, -hz), hz)
        dx, dy, dz = qx - cx, qy - cy, qz - cz
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        if dist > 1e-300:
            n_out[0] = dx / dist
            n_out[1] = dy / dist
            n_out[2] = dz / dist
        else:                                      # on a flat inner box (r > 0 only): its thin axis
            n_out[0] = 1.0 if s0 <= s1 and s0 <= s2 else 0.0
            n_out[1] = 1.0 if n_out[0] == 0.0 and s1 <= s2 else 0.0
            n_out[2] = 1.0 if n_out[0] == 0.0 and n_out[1] == 0.0 else 0.0
        c_out[0] = cx
        c_out[1] = cy
        c_out[2] = cz
        if r > 0.0:
            c_out[0] += r * n_out[0]
            c_out[1] += r * n_out[1]
            c_out[2] += r * n_out[2]
        return dist - r
    c_out[0] = qx
    c_out[1] = qy
    c_out[2] = qz
    n_out[0] = 0.0
    n_out[1] = 0.0
    n_out[2] = 0.0
    if ax >= ay and ax >= az:
        sg = 1.0 if qx >= 0.0 else -1.0
        n_out[0] = sg
        c_out[0] = sg * s0
        return ax - r
    if ay >= az:
        sg = 1.0 if qy >= 0.0 else -1.0
        n_out[1] = sg
        c_out[1] = sg * s1
        return ay - r
    sg = 1.0 if qz >= 0.0 else -1.0
    n_out[2] = sg
    c_out[2] = sg * s2
    return az - r


@njit(cache=True)
def local_sdf(kind, s0, s1, s2, qx, qy, qz, n_out, c_out):
    """Signed distance (m) of local point (qx, qy, qz) to a shape of size (s0, s1, s2) at the origin.

    Writes the local outward normal into ``n_out`` (3,) and the local closest surface point into
    ``c_out`` (3,). Returns +inf for an unknown kind.
    """
    if kind == SPHERE or kind == CAPSULE:
        r = s0
        sz = 0.0
        if kind == CAPSULE:
            h = s1
            sz = min(max(qz, -h), h)
        vx, vy, vz = qx, qy, qz - sz
        nv = math.sqrt(vx * vx + vy * vy + vz * vz)
        if nv > 1e-300:
            n_out[0] = vx / nv
            n_out[1] = vy / nv
            n_out[2] = vz / nv
        elif kind == SPHERE:
            n_out[0] = 0.0
            n_out[1] = 0.0
            n_out[2] = 1.0
        else:
            n_out[0] = 1.0
            n_out[1] = 0.0
            n_out[2] = 0.0
        c_out[0] = n_out[0] * r
        c_out[1] = n_out[1] * r
        c_out[2] = sz + n_out[2] * r
        return nv - r
    if kind == BOX:
        return _box_sdf(s0, s1, s2, 0.0, qx, qy, qz, n_out, c_out)
    if kind == ROUNDED_BOX:
        return _box_sdf(s0, s1, s2, min(s0, min(s1, s2)), qx, qy, qz, n_out, c_out)
    if kind == CYLINDER:
        r, h = s0, s1
        rho = math.sqrt(qx * qx + qy * qy)
        if rho > 1e-300:
            ex, ey = qx / rho, qy / rho
        else:
            ex, ey = 1.0, 0.0
        dr = rho - r
        dz = abs(qz) - h
        sz = 1.0 if qz >= 0.0 else -1.0
        if dr > 0.0 or dz > 0.0:
            crho = min(rho, r)
            cx, cy = ex * crho, ey * crho
            cz = min(max(qz, -h), h)
            dx, dy, dzz = qx - cx, qy - cy, qz - cz
            dist = math.sqrt(dx * dx + dy * dy + dzz * dzz)
            n_out[0] = dx / dist
            n_out[1] = dy / dist
            n_out[2] = dzz / dist
            c_out[0] = cx
            c_out[1] = cy
            c_out[2] = cz
            return dist
        if dr >= dz:
            n_out[0] = ex
            n_out[1] = ey
            n_out[2] = 0.0
            c_out[0] = ex * r
            c_out[1] = ey * r
            c_out[2] = qz
            return dr
        n_out[0] = 0.0
        n_out[1] = 0.0
        n_out[2] = sz
        c_out[0] = qx
        c_out[1] = qy
        c_out[2] = sz * h
        return dz
    return np.inf


@njit(cache=True)
def world_sdf(kind, size, pos, mat, g, x0, x1, x2, nl, cl, n_out, c_out):
    """Signed distance (m) of world point (x0, x1, x2) to geom ``g`` posed by ``pos[g]`` (3) and
    row-major ``mat[g]`` (9); world normal -> ``n_out`` (3,), world closest point -> ``c_out`` (3,).
    ``size`` is (G,3); ``nl, cl`` are (3,) scratch buffers. Indexing whole arrays (no row views)
    keeps the inner loop free of reference counting."""
    dx, dy, dz = x0 - pos[g, 0], x1 - pos[g, 1], x2 - pos[g, 2]
    # local = R^T (x - pos), R row-major: R[i, j] = mat[g, 3 i + j]
    qx = mat[g, 0] * dx + mat[g, 3] * dy + mat[g, 6] * dz
    qy = mat[g, 1] * dx + mat[g, 4] * dy + mat[g, 7] * dz
    qz = mat[g, 2] * dx + mat[g, 5] * dy + mat[g, 8] * dz
    d = local_sdf(kind, size[g, 0], size[g, 1], size[g, 2], qx, qy, qz, nl, cl)
    for i in range(3):
        n_out[i] = mat[g, 3 * i] * nl[0] + mat[g, 3 * i + 1] * nl[1] + mat[g, 3 * i + 2] * nl[2]
        c_out[i] = pos[g, i] + mat[g, 3 * i] * cl[0] + mat[g, 3 * i + 1] * cl[1] + mat[g, 3 * i + 2] * cl[2]
    return d


@njit(cache=True)
def _sdf_points(points, kind, size, pos, mat, dist, normals, closest):
    nl = np.empty(3)
    cl = np.empty(3)
    n = np.empty(3)
    c = np.empty(3)
    for i in range(points.shape[0]):
        # np.bool_ / np.int64, not a literal constant: a literal compiles the callee a second time (numba
        # specialises on literal arguments), seconds to tens of seconds of first-use compile for nothing
        dist[i] = world_sdf(kind, size, pos, mat, np.int64(0), points[i, 0], points[i, 1], points[i, 2], nl, cl, n, c)
        for k in range(3):
            normals[i, k] = n[k]
            closest[i, k] = c[k]


def check_shape(kind: int, size) -> np.ndarray:
    """Validate a shape kind code and its MuJoCo-style size; returns size as a (3,) float array."""
    if int(kind) not in SHAPE_NAMES:
        raise ConfigError(f"unknown shape kind {kind!r}; use SPHERE=0, CAPSULE=1, BOX=2, CYLINDER=3 or ROUNDED_BOX=4")
    flat = np.asarray(size, dtype=np.float64).reshape(-1)[:3]
    size = np.zeros(3)
    size[:len(flat)] = flat
    need = {SPHERE: 1, CAPSULE: 2, BOX: 3, CYLINDER: 2, ROUNDED_BOX: 3}[int(kind)]
    if not np.all(np.isfinite(size[:need])) or np.any(size[:need] <= 0):
        raise ConfigError(f"{SHAPE_NAMES[int(kind)]} size {size[:need].tolist()} m is invalid; "
                          f"the first {need} entries must be positive lengths (MuJoCo geom_size convention)")
    return size


def rotation_as_row_major(mat) -> np.ndarray:
    """Accept a (3,3) or (9,) rotation and return it as a contiguous row-major (9,) float array."""
    m = np.ascontiguousarray(np.asarray(mat, dtype=np.float64).reshape(-1))
    if m.shape != (9,):
        raise ConfigError(f"rotation must be a 3x3 matrix or 9 row-major numbers, got shape {np.shape(mat)}")
    r = m.reshape(3, 3)
    if not np.all(np.isfinite(r)) or np.abs(r @ r.T - np.eye(3)).max() > 1e-6:
        raise ConfigError("rotation is not orthonormal (R R^T != I); pass d.geom_xmat rows or a proper rotation")
    return m


def signed_distance(points, kind: int, size, pos=(0.0, 0.0, 0.0), mat=None):
    """Signed distance of world ``points`` (P,3) m to one posed shape.

    Returns ``(dist (P,) m, negative inside; normals (P,3) unit outward; closest (P,3) m)``.
    ``mat`` is the local-to-world rotation, (3,3) or row-major (9,) as ``d.geom_xmat``; identity if None.
    """
    pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64))
    if pts.ndim == 1:
        pts = pts.reshape(1, 3)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ConfigError(f"points must have shape (P, 3) in m, got {np.shape(points)}")
    size = check_shape(kind, size)
    pos = np.asarray(pos, dtype=np.float64).reshape(3)
    mat = rotation_as_row_major(np.eye(3) if mat is None else mat)
    dist = np.empty(len(pts))
    normals = np.empty((len(pts), 3))
    closest = np.empty((len(pts), 3))
    _sdf_points(pts, int(kind), size.reshape(1, 3), pos.reshape(1, 3), mat.reshape(1, 9), dist, normals, closest)
    return dist, normals, closest
