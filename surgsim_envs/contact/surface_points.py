"""Embedded contact points on the tissue surface triangles (so small tools cannot slip between nodes).

Each surface triangle ``(a, b, c)`` is subdivided ``n`` times along every edge; the lattice points
``(i a + j b + k c) / n`` with ``i + j + k = n`` are its samples. Vertices (``i, j or k = n``) are
the tissue nodes themselves and are not repeated; points on an edge are shared by the two triangles
of that edge and appear once. A sample ``s`` is stored as three node indices and three barycentric
weights ``w`` (non-negative, summing to 1); each step its position and velocity are

    x_s = sum_j w_j x_{node_j},      v_s = sum_j w_j v_{node_j},

and a contact force ``f`` computed at ``x_s`` is given back to the nodes as ``w_j f``. That split
conserves the force (sum w_j = 1) and, with the reaction applied to the tool at ``x_s``, the
angular momentum too (sum_j x_j x w_j f = x_s x f).

On a closed triangulated surface (genus 0: E = 3V - 6, F = 2V - 4) vertices plus samples number
``n^2 (V - 2) + 2``, i.e. ``n^2`` per vertex,
so :class:`~surgsim_envs.contact.ContactModel` gives every contact point ``1/n^2`` of the per-node
penalty stiffness and damping: the stiffness per unit surface area, and hence the force a broad
indenter feels, stays what it was with nodes only.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError

#: most edge subdivisions accepted (n^2 contact points per node; 8 -> 64)
MAX_SUBDIVISIONS = 8


def check_surface(surface, n_nodes: int) -> np.ndarray:
    """Validate surface triangles (F,3) of node indices in [0, n_nodes); returns an int64 copy."""
    tri = np.asarray(surface)
    if tri.ndim != 2 or tri.shape[1] != 3 or len(tri) == 0:
        raise ConfigError(f"surface must be a non-empty (F, 3) array of node indices (tissue.surface), "
                          f"got shape {tri.shape}")
    if not np.issubdtype(tri.dtype, np.integer):
        raise ConfigError(f"surface triangles must hold integer node indices, got dtype {tri.dtype}")
    tri = np.ascontiguousarray(tri, dtype=np.int64)
    if tri.min() < 0 or tri.max() >= n_nodes:
        raise ConfigError(f"surface node indices must lie in [0, {n_nodes}), got [{tri.min()}, {tri.max()}]")
    return tri


def typical_edge_length(positions, surface) -> float:
    """Median length (m) of the surface triangles' edges (each triangle's three edges): the lattice
    spacing h for lattice surfaces (axis edges h, diagonals h sqrt 2 are the minority)."""
    x = np.asarray(positions, dtype=np.float64)
    tri = np.asarray(surface, dtype=np.int64)
    e = np.concatenate([x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 1]], x[tri[:, 0]] - x[tri[:, 2]]])
    return float(np.median(np.linalg.norm(e, axis=1)))


def subdivisions_for_spacing(positions, surface, spacing: float, max_subdivisions: int = MAX_SUBDIVISIONS) -> int:
    """Edge subdivisions ``n`` so that contact points are at most ``spacing`` (m) apart on a typical
    edge: ``n = ceil(median_edge / spacing)``, clamped to [1, max_subdivisions]."""
    validate.positive(spacing, "sample_spacing", unit="m", fix="e.g. the tool tip radius")
    h = typical_edge_length(positions, surface)
    return int(min(max(math.ceil(h / float(spacing) - 1e-9), 1), max_subdivisions))


def surface_samples(surface, subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """Contact samples on the surface triangles, without the vertices and without duplicates.

    surface: (F,3) node indices; subdivisions: n >= 1 edge subdivisions (1 = no samples).
    Returns ``(nodes (S,3) int64, weights (S,3) float64)``: the sample ``s`` sits at
    ``sum_j weights[s, j] * x[nodes[s, j]]``. There are ``E (n-1)`` edge samples (E unique edges)
    and ``F (n-1)(n-2)/2`` interior samples.
    """
    validate.integer(subdivisions, "surface subdivisions", lo=1, hi=MAX_SUBDIVISIONS, fix="1 = nodes only")
    tri = np.asarray(surface, dtype=np.int64).reshape(-1, 3)
    n = int(subdivisions)
    nodes_out, w_out = [np.zeros((0, 3), np.int64)], [np.zeros((0, 3))]
    if n == 1:
        return nodes_out[0], w_out[0]
    # edge samples: one set per unique undirected edge, from its lower to its higher node index
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    edges = np.unique(edges, axis=0)
    t = np.arange(1, n) / n                                   # fraction towards the higher node
    E = len(edges)
    en = np.stack([np.repeat(edges[:, 0], n - 1), np.repeat(edges[:, 1], n - 1), np.repeat(edges[:, 0], n - 1)],
                  axis=1)
    ew = np.stack([np.tile(1.0 - t, E), np.tile(t, E), np.zeros(E * (n - 1))], axis=1)
    nodes_out.append(en)
    w_out.append(ew)
    # interior samples: i, j, k >= 1
    ijk = np.array([(i, j, n - i - j) for i in range(1, n) for j in range(1, n - i)], dtype=np.float64)
    if len(ijk):
        m = len(ijk)
        nodes_out.append(np.repeat(tri, m, axis=0))
        w_out.append(np.tile(ijk / n, (len(tri), 1)))
    return (np.ascontiguousarray(np.concatenate(nodes_out), dtype=np.int64),
            np.ascontiguousarray(np.concatenate(w_out), dtype=np.float64))


@njit(cache=True, inline="always")
def contact_point(c, C, cand, s_nodes, s_w, positions):
    """Contact point ``c`` of the contact kernel (:mod:`surgsim_envs.contact.model`): (x0, x1, x2, i, a, b, e, wa, wb, we), its position
    (m), its node ``i`` if it is a candidate node (c < C), else the surface sample's nodes (a, b, e) and
    weights (wa, wb, we); the entries of the other kind are 0."""
    if c < C:
        i = cand[c]
        return positions[i, 0], positions[i, 1], positions[i, 2], i, 0, 0, 0, 0.0, 0.0, 0.0
    s = c - C
    a, b, e = s_nodes[s, 0], s_nodes[s, 1], s_nodes[s, 2]
    wa, wb, we = s_w[s, 0], s_w[s, 1], s_w[s, 2]
    x0 = wa * positions[a, 0] + wb * positions[b, 0] + we * positions[e, 0]
    x1 = wa * positions[a, 1] + wb * positions[b, 1] + we * positions[e, 1]
    x2 = wa * positions[a, 2] + wb * positions[b, 2] + we * positions[e, 2]
    return x0, x1, x2, 0, a, b, e, wa, wb, we
