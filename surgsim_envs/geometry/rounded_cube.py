"""A cube with round corners as a surface grid (Zhong et al. 2016, Figs. 9.2-9.5): no tets, only a surface.

The cube's six faces are each an ``n x n`` grid of points (shared along edges and corners, so the
surface has ``6 n^2 - 12 n + 8`` points: n = 13 gives 866, n = 14 gives 1,016). The grid is pushed
radially onto the superellipsoid ``|x|^p + |y|^p + |z|^p = (size/2)^p`` (``p = exponent``; large p
is a sharp cube, p = 2 a sphere), which rounds the corners and edges. Every quad is split into two
triangles with outward normals; the quads are kept (``volume.quads``) for the finite-difference
scheme of eq. 9.9 on regular grids. The centre is at the origin. All lengths in m.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.volume import Volume

#: default side (m) and superellipsoid exponent of the rounded cube
CUBE_SIZE = 0.1
CUBE_EXPONENT = 8.0


def grid_points_for(n: int) -> int:
    """Number of surface points of a cube whose faces are n x n grids."""
    return 6 * n * n - 12 * n + 8


def grid_n_for_points(points: int) -> int:
    """The face grid size n whose point count is closest to ``points``."""
    if not (isinstance(points, (int, np.integer)) and points >= 8):
        raise ConfigError(f"points must be an integer >= 8 (a cube has 8 corners), got {points!r}")
    return min(range(2, 200), key=lambda n: abs(grid_points_for(n) - int(points)))


def rounded_cube_surface(n: int, size: float = CUBE_SIZE, exponent: float = CUBE_EXPONENT):
    """``(nodes (N,3) m, triangles (2Q,3), quads (Q,4))`` of a round-cornered cube with n x n faces.

    Quads and triangles are ordered counter-clockwise seen from outside (outward normals)."""
    if not (isinstance(n, (int, np.integer)) and 2 <= n <= 200):
        raise ConfigError(f"face grid size n must be an integer in 2..200, got {n!r}")
    if not (np.isfinite(size) and 0 < size < 2.0):
        raise ConfigError(f"size must be a side length in m in (0, 2), got {size!r}")
    if not (np.isfinite(exponent) and exponent >= 2.0):
        raise ConfigError(f"exponent must be >= 2 (2 = sphere, large = sharp cube), got {exponent!r}")
    t = np.linspace(-1.0, 1.0, int(n))
    index: dict[tuple[int, int, int], int] = {}
    points: list[tuple[float, float, float]] = []
    quads = []
    # each face: fixed axis a at side s; (u, v) the other two axes so that u x v points outward
    for a in range(3):
        u_ax, v_ax = (a + 1) % 3, (a + 2) % 3
        for s in (-1, 1):
            ids = np.empty((n, n), dtype=np.int64)
            for i in range(n):
                for j in range(n):
                    key = [0, 0, 0]
                    key[a] = s * (n - 1)
                    key[u_ax] = 2 * i - (n - 1)
                    key[v_ax] = 2 * j - (n - 1)
                    k = tuple(key)
                    if k not in index:
                        q = [0.0, 0.0, 0.0]
                        q[a], q[u_ax], q[v_ax] = float(s), t[i], t[j]
                        index[k] = len(points)
                        points.append(tuple(q))
                    ids[i, j] = index[k]
            for i in range(n - 1):
                for j in range(n - 1):
                    quad = [ids[i, j], ids[i + 1, j], ids[i + 1, j + 1], ids[i, j + 1]]
                    quads.append(quad if s > 0 else quad[::-1])
    cube = np.asarray(points, dtype=np.float64)
    radius = np.sum(np.abs(cube) ** exponent, axis=1) ** (1.0 / exponent)
    nodes = cube / radius[:, None] * (size / 2.0)
    quads = np.asarray(quads, dtype=np.int32)
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]).astype(np.int32)
    return nodes, tris, quads


def rounded_cube_volume(spacing: float | None = None, size: float = CUBE_SIZE, exponent: float = CUBE_EXPONENT,
                        points: int | None = None, name: str = "rounded_cube") -> Volume:
    """Surface-only :class:`Volume` (no tets) of the round-cornered cube, centred at the origin.

    Give either ``points`` (the count is matched as closely as the n x n faces allow: 900 -> 866)
    or ``spacing`` (m, the grid step along a face); default about 900 points."""
    if points is not None:
        n = grid_n_for_points(points)
    elif spacing is not None:
        if not (isinstance(spacing, (int, float)) and np.isfinite(spacing) and 0 < spacing < size):
            raise ConfigError(f"spacing must be a length in m in (0, size={size}), got {spacing!r}")
        n = max(2, int(round(size / spacing)) + 1)
    else:
        n = grid_n_for_points(900)
    nodes, tris, quads = rounded_cube_surface(n, size, exponent)
    vol = Volume(nodes, np.zeros((0, 4), dtype=np.int32), tris, name=name)
    vol.quads = quads
    return vol
