"""Tri-ray node snapping (Lin et al. 2008, section 2.3) with an inversion guard.

Rays are cast along the three lattice axes through the lattice nodes. Where a ray crosses the
surface, the lattice node closest to the crossing along that ray is snapped onto the crossing if
it lies within ``max_snap * spacing`` (Lin et al. 2008 eq. 2.3 uses half the spacing) and it is a
boundary node of the kept cells. A node with candidates from several axes takes the nearest one.
Boundary nodes no ray reached can optionally be projected to the closest surface point (same
distance limit). Finally :func:`guard_snaps` shrinks (halves, then undoes) the snaps of nodes in
any tet whose quality fell below ``min_quality``, so snapping never inverts or flattens a tet.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.geometry.axis_rays import RAY_JITTER, axis_line_hits

_Q_NORM = 6.0 * np.sqrt(2.0)


def tet_quality(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Shape quality 6*sqrt(2) V / l_rms^3 per tet: 1 for a regular tet, ~0.66 for a Kuhn cube tet,
    0 for a flat one and negative for an inverted one (dimensionless)."""
    p = nodes[tets]
    e = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0],
                  p[:, 2] - p[:, 1], p[:, 3] - p[:, 1], p[:, 3] - p[:, 2]], axis=1)
    l_rms = np.sqrt(np.mean(np.einsum("tek,tek->te", e, e), axis=1))
    vol = np.einsum("ij,ij->i", e[:, 0], np.cross(e[:, 1], e[:, 2])) / 6.0
    return _Q_NORM * vol / np.maximum(l_rms, 1e-300) ** 3


def tri_ray_snap(triangles: np.ndarray, origin: np.ndarray, h: float, counts: np.ndarray,
                 lattice_index: np.ndarray, movable: np.ndarray, max_snap: float = 0.5) -> np.ndarray:
    """Snap displacements (M, 3), m, for the mesh nodes at lattice positions ``lattice_index`` (M, 3).

    triangles: (F, 3, 3) surface, m; ``origin`` (3,) and ``h`` define lattice node positions
    ``origin + h * index``; ``counts`` (3,) nodes per axis; ``movable`` (M,) bool marks the nodes
    allowed to snap (boundary nodes). Only axis-aligned moves of at most ``max_snap * h``.
    """
    m = len(lattice_index)
    counts = np.asarray(counts, dtype=np.int64)
    flat = np.ravel_multi_index(lattice_index.T, counts)
    lookup = np.full(int(counts.prod()), -1, dtype=np.int64)
    lookup[flat] = np.arange(m)
    best_d = np.full(m, np.inf)
    disp = np.zeros((m, 3))
    for axis in range(3):
        ua, va = (axis + 1) % 3, (axis + 2) % 3
        nu, nv = int(counts[ua]), int(counts[va])
        u0 = origin[ua] + RAY_JITTER[ua] * h
        v0 = origin[va] + RAY_JITTER[va] * h
        line, t, _ = axis_line_hits(triangles, axis, u0, v0, h, nu, nv)
        if len(t) == 0:
            continue
        k = np.rint((t - origin[axis]) / h).astype(np.int64)
        ok = (k >= 0) & (k < counts[axis])
        line, t, k = line[ok], t[ok], k[ok]
        idx = np.empty((len(k), 3), dtype=np.int64)
        idx[:, axis] = k
        idx[:, ua] = line // nv
        idx[:, va] = line % nv
        node = lookup[np.ravel_multi_index(idx.T, counts)]
        d = t - (origin[axis] + k * h)
        ok = (node >= 0) & (np.abs(d) <= max_snap * h)
        node, d = node[ok], d[ok]
        ok = movable[node]
        node, d = node[ok], d[ok]
        # nearest candidate per node (over this axis and the previous ones)
        order = np.lexsort((np.abs(d), node))
        node, d = node[order], d[order]
        first = np.ones(len(node), dtype=bool)
        first[1:] = node[1:] != node[:-1]
        node, d = node[first], d[first]
        better = np.abs(d) < best_d[node]
        node, d = node[better], d[better]
        best_d[node] = np.abs(d)
        disp[node] = 0.0
        disp[node, axis] = d
    return disp


def project_to_surface(surface, points: np.ndarray, max_dist: float) -> np.ndarray:
    """Displacements (P, 3), m, moving ``points`` to their closest point on the trimesh ``surface``;
    zero where that point is farther than ``max_dist`` (m)."""
    if len(points) == 0:
        return np.zeros((0, 3))
    closest, dist, _ = surface.nearest.on_surface(points)
    disp = closest - points
    disp[~(dist <= max_dist)] = 0.0
    return disp


def guard_snaps(rest: np.ndarray, disp: np.ndarray, tets: np.ndarray, min_quality: float = 0.15,
                halvings: int = 3) -> tuple[np.ndarray, int]:
    """Shrink snaps until every tet has :func:`tet_quality` >= ``min_quality``.

    ``rest`` (N, 3) lattice positions (all tets good there), ``disp`` (N, 3) snap displacements, m.
    In each pass, the node with the largest snap in every bad tet has its snap halved (at most
    ``halvings`` times per node, then undone). Ends when no tet is bad; terminates because each pass
    shrinks at least one snap and the unsnapped lattice is good. Returns the accepted displacements
    and how many nodes had their snap reduced.
    """
    disp = disp.copy()
    shrunk = np.zeros(len(rest), dtype=np.int64)
    while True:
        q = tet_quality(rest + disp, tets)
        bad = np.flatnonzero(q < min_quality)
        if len(bad) == 0:
            break
        size = np.linalg.norm(disp, axis=1)
        local = tets[bad]
        pick = local[np.arange(len(bad)), np.argmax(size[local], axis=1)]
        pick = np.unique(pick[size[pick] > 0.0])
        if len(pick) == 0:  # bad already at rest: nothing snapping can fix
            break
        shrunk[pick] += 1
        full = shrunk[pick] > halvings
        disp[pick[full]] = 0.0
        disp[pick[~full]] *= 0.5
    return disp, int(np.count_nonzero(shrunk))
