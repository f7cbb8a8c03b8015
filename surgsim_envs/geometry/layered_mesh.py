"""A :class:`~surgsim_envs.geometry.layers.LayeredVolume` from any tet mesh whose nodes are not on a
tensor grid: the snapped organ lattices of the grasp and slippage tasks (tri-ray snapping of a
Kuhn lattice inside the organ's surface, :mod:`surgsim_envs.geometry.lattice`) or a user mesh.

The layered model (Lin et al. 2008) joins each node to its neighbouring bounding box (NBB): one
neighbour per axis direction (Fig. 2.11). On a snapped lattice these are the lattice's axis edges,
bent where the boundary nodes were snapped; here they are recovered from the mesh's own edges:

* lattice coordinates: those the lattice was built with (``volume.lattice_index``, kept by
  ``lattice_volume``, ``organ_volume`` and the scene's placement when not rotated); for a mesh
  without them, nodes still on the lattice (spacing h: the most common axis-edge length) get
  theirs by rounding and moved nodes the most common coordinates their placed neighbours' edges
  give (:func:`lattice_coordinates`; fine for small snaps, a ConfigError when two nodes land on one
  site: the closest-point projection of organ lattices moves nodes up to 0.9 h). The NBB springs are the mesh edges one lattice step along an axis,
  so every spring is listed at both ends and the coordinates are consistent around every loop;
* spring cross-section ``A_ij = L0_ij^2 n_ij / 6`` with ``n_ij`` the tets sharing the edge: exactly
  the paper's "quarter cell faces around the edge" on a Kuhn lattice (an interior axis edge lies in
  6 Kuhn tets of its 4 cells: h^2; on a flat face 3: h^2 / 2; tested), an estimate elsewhere;
* node and spring materials from the tets' labels (``materials`` {label: Material}), as
  :func:`~surgsim_envs.geometry.layers.layered_from_grid` does.

Bad input (no axis-aligned edges, two nodes on one lattice site: not a snapped lattice) raises
ConfigError. Units: m.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.layers import DIRECTIONS, LayeredVolume, _spring_materials
from surgsim_envs.geometry.volume import Volume


def edge_tet_counts(tets: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Unique edges (E,2) (i < j) of the tets and the number of tets sharing each."""
    tets = np.asarray(tets, dtype=np.int64)
    e = np.stack([tets[:, [0, 0, 0, 1, 1, 2]].ravel(), tets[:, [1, 2, 3, 2, 3, 3]].ravel()], axis=1)
    e.sort(axis=1)
    key, counts = np.unique(e[:, 0] * n + e[:, 1], return_counts=True)
    return np.stack([key // n, key % n], axis=1), counts


def lattice_coordinates(X: np.ndarray, edges: np.ndarray, h: float) -> np.ndarray:
    """(N,3) int lattice coordinates of the nodes of a (snapped) lattice of spacing ``h`` m.

    Nodes still on the lattice (interior nodes: ``(X - X_ref) / h`` integral to 1e-6, X_ref the node
    in the most edges) get theirs by rounding; a snapped node (moved up to ``h / 2`` along one ray)
    takes the most common ``c_i + round((X_j - X_i) / h)`` over its already placed edge neighbours
    i, unsnapped ones first (passes outwards from the lattice nodes)."""
    n = len(X)
    deg = np.bincount(edges.ravel(), minlength=n)
    ref = X[int(np.argmax(deg))]
    q = (X - ref) / h
    idx = np.round(q).astype(np.int64)
    known = np.all(np.abs(q - idx) < 1e-6, axis=1)
    i = np.concatenate([edges[:, 0], edges[:, 1]])
    j = np.concatenate([edges[:, 1], edges[:, 0]])
    while not known.all():
        ok = known[i] & ~known[j]
        if not ok.any():          # a piece with no lattice node: start it by rounding
            known[np.flatnonzero(~known)[0]] = True
            continue
        cand = idx[i[ok]] + np.round((X[j[ok]] - X[i[ok]]) / h).astype(np.int64)
        keys, counts = np.unique(np.column_stack([j[ok], cand]), axis=0, return_counts=True)
        order = np.lexsort((-counts, keys[:, 0]))           # per node, the most common candidate first
        keys = keys[order]
        first = np.r_[True, keys[1:, 0] != keys[:-1, 0]]
        idx[keys[first, 0]] = keys[first, 1:]
        known[keys[first, 0]] = True
    return idx


def nbb_from_lattice(idx: np.ndarray, edges: np.ndarray, n: int) -> np.ndarray:
    """(N,6) int32 NBB neighbour per direction (-1 none): the mesh edges one lattice step along an axis."""
    out = np.full((n, 6), -1, dtype=np.int32)
    off = idx[edges[:, 1]] - idx[edges[:, 0]]
    for d, unit in enumerate(DIRECTIONS):
        fwd = np.all(off == np.asarray(unit), axis=1)
        out[edges[fwd, 0], d] = edges[fwd, 1]
        out[edges[fwd, 1], d ^ 1] = edges[fwd, 0]
    return out


def lattice_spacing(X: np.ndarray, edges: np.ndarray) -> float:
    """Spacing h (m) of the lattice: the most common length (to 1e-9 relative) of the edges along an
    axis (the unsnapped ones all have it exactly; snapped boundary edges spread around it)."""
    v = X[edges[:, 1]] - X[edges[:, 0]]
    length = np.linalg.norm(v, axis=1)
    axial = np.abs(v).max(axis=1) > (1.0 - 1e-9) * length
    if not axial.any():
        raise ConfigError("the layered model needs a lattice-like tet mesh (no edge is aligned with an axis); "
                          "build it with surgsim_envs.geometry.lattice_volume or organ_volume")
    scale = float(length[axial].max())
    keys, counts = np.unique(np.round(length[axial] / scale, 9), return_counts=True)
    return float(keys[np.argmax(counts)] * scale)


def layered_from_mesh(volume: Volume, materials: dict, name: str | None = None) -> LayeredVolume:
    """LayeredVolume on ``volume``'s own nodes and tets (module docstring); ``materials`` {label: Material}."""
    X = np.asarray(volume.nodes, dtype=np.float64)
    n = len(X)
    edges, counts = edge_tet_counts(volume.tets, n)
    spacing = lattice_spacing(X, edges)
    index = getattr(volume, "lattice_index", None)   # kept by lattice_volume / organ_volume / the scene
    if index is None or len(index) != n:
        index = lattice_coordinates(X, edges, spacing)
    index = np.asarray(index, dtype=np.int64)
    neighbours = nbb_from_lattice(index, edges, n)
    flat = index - index.min(axis=0)
    if len(np.unique(flat, axis=0)) != n:
        raise ConfigError(f"volume '{volume.name}': two nodes share a lattice site (not a snapped lattice of "
                          f"spacing {spacing:.4g} m); the layered model needs surgsim_envs.geometry.lattice_volume meshes")
    lookup = dict(zip((edges[:, 0] * n + edges[:, 1]).tolist(), counts.tolist()))
    area = np.zeros((n, 6))
    for d in range(6):
        j = neighbours[:, d].astype(np.int64)
        ok = np.flatnonzero(j >= 0)
        a, b = np.minimum(ok, j[ok]), np.maximum(ok, j[ok])
        cnt = np.array([lookup[k] for k in (a * n + b).tolist()], dtype=np.float64)
        area[ok, d] = np.sum((X[j[ok]] - X[ok]) ** 2, axis=1) * cnt / 6.0
    labels = sorted(set(np.unique(volume.labels).tolist()))
    missing = [k for k in labels if k not in materials]
    if missing:
        raise ConfigError(f"volume '{volume.name}': no material for region label(s) {missing}")
    names = [f"label{k}" for k in labels]
    table = {f"label{k}": materials[k] for k in labels}
    node_material = np.searchsorted(labels, volume.node_labels).astype(np.int64)
    on_iface = np.full(n, -1, dtype=np.int64)
    out = LayeredVolume(X, volume.tets, volume.surface, volume.labels, name=name or volume.name,
                        node_labels=volume.node_labels, lattice_index=index,
                        neighbours=neighbours,
                        spring_area=area, spring_material=_spring_materials(neighbours, node_material, on_iface),
                        node_material=node_material, node_interface=on_iface, material_names=names,
                        material_table=table, layer_names=names, interface_names=[], rigid_materials=(),
                        spacing=spacing)
    src = getattr(volume, "source_surface", None)
    if src is not None:
        out.source_surface = src
    return out


__all__ = ["layered_from_mesh", "lattice_coordinates", "lattice_spacing", "nbb_from_lattice", "edge_tet_counts"]
