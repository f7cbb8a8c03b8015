"""Lattice tets on a graded tensor grid: a closed surface filled with nodes that are fine where a
load needs them and coarse elsewhere.

:func:`lattice_volume` fills a surface with a uniform lattice. Here each axis carries its own node
coordinates (ascending, e.g. :func:`surgsim_envs.geometry.graded_axis.graded_axis`: fine around a
point, growing geometrically to a coarse spacing), and the fill runs in grid space: each axis is
mapped piecewise linearly onto its cell index (x -> xi, node k at xi = k), the surface is mapped
with it, :func:`lattice_volume` fills the mapped surface at spacing 1 (cells, Kuhn tets, tri-ray
snapping, the inversion guard, all in grid space) and the nodes are mapped back. So every rule of
the uniform lattice holds cell by cell (a boundary node snaps at most half its local cell along an
axis), the tets stay conforming, and neighbouring cells differ by the grid's growth ratio.

The map is linear inside each grid cell and bends at grid lines, so a surface triangle crossing a
grid line would bend there; the surface is first subdivided to edges of at most a quarter of the
finest cell, so its mapped image is the same surface to within the bend over a quarter cell. The
lattice's own nodes lie between grid lines (the fill centres its lattice on the mapped surface), so
a node's cell is a blend of two neighbouring grid cells. Units: m.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.lattice import as_trimesh, lattice_volume
from surgsim_envs.geometry.volume import Volume, tet_signed_volumes

#: surface edges are subdivided to at most this fraction of the finest grid cell before the map
SUBDIVIDE_FRACTION = 0.25
#: grid cells the axes must reach beyond the surface on each side (the uniform fill keeps one)
MARGIN_CELLS = 2


def _axis(coords, name: str) -> np.ndarray:
    c = np.asarray(coords, dtype=np.float64)
    if c.ndim != 1 or len(c) < 4 or not np.all(np.isfinite(c)) or np.any(np.diff(c) <= 0.0):
        raise ConfigError(f"mapped lattice: the {name} axis must be >= 4 finite, strictly ascending node coordinates "
                          f"(m), got {np.asarray(coords).shape} values; build it with geometry.graded_axis.graded_axis")
    return c


def to_grid(x: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """Grid coordinate xi of positions ``x`` (m) on the axis ``coords``: node k at xi = k, linear in
    each cell, extended linearly with the end cells beyond the axis."""
    xi = np.interp(x, coords, np.arange(len(coords), dtype=np.float64))
    lo, hi = x < coords[0], x > coords[-1]
    xi[lo] = (x[lo] - coords[0]) / (coords[1] - coords[0])
    xi[hi] = len(coords) - 1 + (x[hi] - coords[-1]) / (coords[-1] - coords[-2])
    return xi


def from_grid(xi: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """Positions (m) of grid coordinates ``xi`` on the axis ``coords`` (inverse of :func:`to_grid`)."""
    n = len(coords)
    x = np.interp(xi, np.arange(n, dtype=np.float64), coords)
    lo, hi = xi < 0.0, xi > n - 1
    x[lo] = coords[0] + xi[lo] * (coords[1] - coords[0])
    x[hi] = coords[-1] + (xi[hi] - (n - 1)) * (coords[-1] - coords[-2])
    return x


def mapped_lattice_volume(surface, axes, name: str = "volume", **lattice_options) -> Volume:
    """Tet Volume filling the closed ``surface`` (trimesh or (vertices, faces), m) with lattice tets
    whose nodes follow the grid ``axes`` = (x coords, y coords, z coords), each ascending (m) and
    reaching :data:`MARGIN_CELLS` cells beyond the surface on both sides (module docstring).
    ``lattice_options`` go to :func:`lattice_volume` (``snap``, ``max_snap``, ``min_quality``, ...);
    its snap and projection limits are fractions of the local cell. The Volume carries
    ``lattice_index`` (the grid-space lattice's)."""
    import trimesh

    mesh = as_trimesh(surface)
    coords = [_axis(a, n) for a, n in zip(axes, "xyz")] if len(axes) == 3 else None
    if coords is None:
        raise ConfigError(f"mapped lattice: axes must be three coordinate arrays (x, y, z), got {len(axes)}")
    lo, hi = mesh.bounds
    for k, c in enumerate(coords):
        d = np.diff(c)
        if c[0] > lo[k] - MARGIN_CELLS * d[0] or c[-1] < hi[k] + MARGIN_CELLS * d[-1]:
            raise ConfigError(f"mapped lattice: the {'xyz'[k]} axis [{c[0]:.4g}, {c[-1]:.4g}] m must reach "
                              f"{MARGIN_CELLS} cells beyond the surface's [{lo[k]:.4g}, {hi[k]:.4g}] m; extend it")
    finest = min(float(np.diff(c).min()) for c in coords)
    v, f = trimesh.remesh.subdivide_to_size(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces),
                                            max_edge=SUBDIVIDE_FRACTION * finest, max_iter=20)
    grid_vertices = np.stack([to_grid(v[:, k], coords[k]) for k in range(3)], axis=1)
    grid_mesh = trimesh.Trimesh(grid_vertices, f, process=False)
    vol = lattice_volume(grid_mesh, 1.0, name=name, **lattice_options)
    nodes = np.stack([from_grid(vol.nodes[:, k], coords[k]) for k in range(3)], axis=1)
    out = Volume(nodes, vol.tets, vol.surface, vol.labels, name)
    if np.any(tet_signed_volumes(nodes, vol.tets) <= 0.0):
        raise ConfigError("mapped lattice: the map back from grid space inverted a tet; use a smaller growth ratio")
    out.lattice_index = vol.lattice_index
    return out
