"""Axis-aligned ray casting on a regular grid of lines (the tri-dexel of Lin et al. 2008).

For one axis ``a`` and a regular 2-D grid of lines parallel to ``a`` (origin ``(u0, v0)`` in the two
other axes, line pitch ``h``), :func:`axis_line_hits` returns every crossing of every line with a
closed triangle surface: the line index, the coordinate along ``a`` (m) and the crossing sign
(+1 = leaving the solid when moving along +a, for an outward-oriented surface).

Each triangle is tested only against the lines inside its projected bounding box, so the cost is
O(F + hits) (numba). Callers offset the grid by a tiny irrational fraction of ``h`` so that lines do
not pass exactly through mesh edges or vertices (which would double-count crossings).
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: fractions of the spacing by which ray grids are shifted off lattice lines (avoid edge hits)
RAY_JITTER = np.array([0.53771, 0.81229, 0.29137]) * 1e-6


@njit(cache=True)
def _cast(tri, axis, u0, v0, h, nu, nv, fill, out_line, out_t, out_sign):
    """Count (fill=False) or record (fill=True) line/triangle crossings; returns the count."""
    ua = (axis + 1) % 3
    va = (axis + 2) % 3
    k = 0
    for f in range(tri.shape[0]):
        pu0 = tri[f, 0, ua]
        pv0 = tri[f, 0, va]
        pu1 = tri[f, 1, ua]
        pv1 = tri[f, 1, va]
        pu2 = tri[f, 2, ua]
        pv2 = tri[f, 2, va]
        area = (pu1 - pu0) * (pv2 - pv0) - (pv1 - pv0) * (pu2 - pu0)
        if area == 0.0:
            continue  # triangle parallel to the rays
        umin = min(pu0, min(pu1, pu2))
        umax = max(pu0, max(pu1, pu2))
        vmin = min(pv0, min(pv1, pv2))
        vmax = max(pv0, max(pv1, pv2))
        i0 = max(int(np.ceil((umin - u0) / h)), 0)
        i1 = min(int(np.floor((umax - u0) / h)), nu - 1)
        j0 = max(int(np.ceil((vmin - v0) / h)), 0)
        j1 = min(int(np.floor((vmax - v0) / h)), nv - 1)
        if i0 > i1 or j0 > j1:
            continue
        inv = 1.0 / area
        sgn = 1 if area > 0 else -1
        for i in range(i0, i1 + 1):
            qu = u0 + i * h
            for j in range(j0, j1 + 1):
                qv = v0 + j * h
                w0 = ((pu1 - qu) * (pv2 - qv) - (pv1 - qv) * (pu2 - qu)) * inv
                w1 = ((pu2 - qu) * (pv0 - qv) - (pv2 - qv) * (pu0 - qu)) * inv
                w2 = 1.0 - w0 - w1
                if w0 < 0.0 or w1 < 0.0 or w2 < 0.0:
                    continue
                if fill:
                    out_line[k] = i * nv + j
                    out_t[k] = w0 * tri[f, 0, axis] + w1 * tri[f, 1, axis] + w2 * tri[f, 2, axis]
                    out_sign[k] = sgn
                k += 1
    return k


def axis_line_hits(triangles: np.ndarray, axis: int, u0: float, v0: float, h: float, nu: int, nv: int):
    """Crossings of the lines parallel to ``axis`` with a triangle soup.

    triangles: (F, 3, 3) vertex coordinates, m. Lines sit at ``(u0 + i h, v0 + j h)`` in the axes
    ``(axis+1) % 3, (axis+2) % 3`` for ``i < nu, j < nv``. Returns ``line`` (H,) int64 = ``i * nv + j``,
    ``t`` (H,) float64 coordinate along ``axis`` (m) and ``sign`` (H,) int8, sorted by (line, t).
    """
    tri = np.ascontiguousarray(triangles, dtype=np.float64)
    dummy_i = np.zeros(0, np.int64)
    dummy_f = np.zeros(0, np.float64)
    dummy_s = np.zeros(0, np.int8)
    n = _cast(tri, int(axis), float(u0), float(v0), float(h), int(nu), int(nv), False, dummy_i, dummy_f, dummy_s)
    line = np.empty(n, np.int64)
    t = np.empty(n, np.float64)
    sign = np.empty(n, np.int8)
    _cast(tri, int(axis), float(u0), float(v0), float(h), int(nu), int(nv), True, line, t, sign)
    order = np.lexsort((t, line))
    return line[order], t[order], sign[order]


def points_inside_along_lines(line: np.ndarray, t: np.ndarray, query_line: np.ndarray,
                              query_t: np.ndarray) -> np.ndarray:
    """Parity inside test: a query point (line, coordinate) is inside if an odd number of the
    crossings on its line lie below it. ``line``/``t`` must be sorted by (line, t)."""
    if len(t) == 0:
        return np.zeros(len(query_t), dtype=bool)
    tmin, tmax = float(t.min()), float(t.max())
    span = max(tmax - tmin, 1e-12) * 4.0
    lo = tmin - span  # map t into (0, 1) strictly: key = line + (t - lo) / (3 span)
    key = line + (t - lo) / (3.0 * span)
    qt = np.clip(query_t, lo + 1e-9 * span, lo + 2.999 * span)
    qkey = query_line + (qt - lo) / (3.0 * span)
    below = np.searchsorted(key, qkey, side="left")
    start = np.searchsorted(key, query_line.astype(np.float64), side="left")
    return ((below - start) % 2) == 1
