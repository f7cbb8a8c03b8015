"""The box cells of a tensor-product lattice: a :class:`~surgsim_envs.geometry.Volume` whose nodes
are every point of three axes (x, y, z) and whose tets split each box between neighbouring axis
values (the box lattices of :func:`~surgsim_envs.geometry.box_volume` and the layered walls of
:mod:`surgsim_envs.geometry.wall_lattice`), seen as 8-node hexahedra. Units: m."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from surgsim_envs.errors import ConfigError

#: hexahedron corner order: the bottom face (z low) counter-clockwise from (x low, y low), then the top
CORNER_SIGNS = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                         [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=float)


@dataclass(frozen=True)
class BoxCells:
    """``hexes`` (H, 8) node indices in :data:`CORNER_SIGNS` order, ``sizes`` (H, 3) m edge lengths,
    ``centroids`` (H, 3) m, ``labels`` (H,) the volume label of each cell's tets, ``axes`` the three
    node axes (m, ascending) and ``cell_of_tet`` (T,) the cell each tet lies in."""

    hexes: np.ndarray
    sizes: np.ndarray
    centroids: np.ndarray
    labels: np.ndarray
    axes: tuple
    cell_of_tet: np.ndarray


def _axis(values: np.ndarray, span: float) -> np.ndarray:
    """The distinct values of one coordinate (m), merged within a billionth of the span."""
    v = np.sort(values)
    keep = np.concatenate([[True], np.diff(v) > 1e-9 * span])
    return v[keep]


def box_cells(volume) -> BoxCells:
    """The hexahedra of ``volume``'s lattice; ConfigError when it is not a tensor-product lattice
    (an organ filled from a surface mesh: its boundary cells are cut)."""
    nodes = np.asarray(volume.nodes, dtype=np.float64)
    span = float(np.ptp(nodes, axis=0).max()) or 1.0
    axes = tuple(_axis(nodes[:, k], span) for k in range(3))
    shape = tuple(len(a) for a in axes)
    ijk = np.stack([np.clip(np.searchsorted(axes[k], nodes[:, k] - 1e-9 * span), 0, shape[k] - 1) for k in range(3)], 1)
    on_axes = np.all([np.abs(axes[k][ijk[:, k]] - nodes[:, k]) <= 1e-9 * span for k in range(3)], axis=0)
    index = -np.ones(shape, dtype=np.int64)
    index[ijk[:, 0], ijk[:, 1], ijk[:, 2]] = np.arange(len(nodes))
    if min(shape) < 2 or len(nodes) != int(np.prod(shape)) or not on_axes.all() or np.any(index < 0):
        raise ConfigError(f"volume '{volume.name}' is not a box lattice (its {len(nodes)} nodes are not every point of "
                          f"{shape[0]} x {shape[1]} x {shape[2]} axis values): a hexahedral model needs a box or "
                          "layered-wall lattice (geometry.box_volume, geometry.wall_lattice); use 'fem_static' "
                          "(tets) for other shapes")
    i, j, k = (a.ravel() for a in np.meshgrid(*(np.arange(n - 1) for n in shape), indexing="ij"))
    hexes = np.stack([index[i, j, k], index[i + 1, j, k], index[i + 1, j + 1, k], index[i, j + 1, k],
                      index[i, j, k + 1], index[i + 1, j, k + 1], index[i + 1, j + 1, k + 1], index[i, j + 1, k + 1]], 1)
    x, y, z = axes
    sizes = np.stack([x[i + 1] - x[i], y[j + 1] - y[j], z[k + 1] - z[k]], 1)
    centroids = np.stack([(x[i + 1] + x[i]) / 2, (y[j + 1] + y[j]) / 2, (z[k + 1] + z[k]) / 2], 1)
    tets = np.asarray(volume.tets, dtype=np.int64)
    corner = ijk[tets].min(axis=1)                                   # each tet's cell: its lowest corner
    if np.any(ijk[tets].max(axis=1) - corner > 1):
        raise ConfigError(f"volume '{volume.name}': a tet spans more than one box cell; not a box lattice")
    cell_of_tet = (corner[:, 0] * (shape[1] - 1) + corner[:, 1]) * (shape[2] - 1) + corner[:, 2]
    counts = np.bincount(cell_of_tet, minlength=len(hexes))
    if np.any(counts == 0):
        raise ConfigError(f"volume '{volume.name}': {int(np.sum(counts == 0))} box cells hold no tet; not a filled box "
                          "lattice")
    labels = np.zeros(len(hexes), dtype=np.int32)
    labels[cell_of_tet] = volume.labels                              # a cell's tets share its layer
    mixed = np.zeros(len(hexes), dtype=bool)
    np.logical_or.at(mixed, cell_of_tet, labels[cell_of_tet] != volume.labels)
    if mixed.any():
        raise ConfigError(f"volume '{volume.name}': {int(mixed.sum())} box cells hold tets of different labels; a "
                          "hexahedron carries one material (put the layer interfaces on lattice planes)")
    return BoxCells(hexes, sizes, centroids, labels, axes, cell_of_tet)


__all__ = ["CORNER_SIGNS", "BoxCells", "box_cells"]
