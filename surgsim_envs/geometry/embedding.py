"""Embed a fine visual surface in the tetrahedra of a simulation Volume (linear interpolation).

Every vertex ``y`` of the visual surface is tied to one tet ``(n0, n1, n2, n3)`` of the volume by
its barycentric coordinates ``w`` (``sum w = 1``, ``y = sum_j w_j X_{n_j}`` at rest). When the
tissue deforms, the vertex follows the tet:

    y(t) = sum_j w_j x_{n_j}(t)            (:func:`interpolate`, numba)

Vertices inside the lattice use the tet that contains them (all ``w_j >= 0``, up to round-off).
Vertices outside every tet (the lattice boundary is lumpy after snapping, so the smooth surface
pokes out of it in places) use the nearest tet with extrapolated coordinates; each coordinate is
clamped to ``[-max_extrapolation, 1 + max_extrapolation]`` (and the set renormalised to sum 1) so a
vertex far from every tet cannot amplify the tet's deformation. Because the weights sum to one,
the embedded surface follows any affine deformation of the lattice exactly, and an unclamped
vertex is reproduced exactly at rest. Units: m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError

#: default clamp of extrapolated barycentric coordinates (1 = up to one tet size outside)
MAX_EXTRAPOLATION = 1.0
#: candidate tets tested per vertex (nearest by centroid)
N_CANDIDATES = 16


@njit(cache=True)
def interpolate(positions, tet_nodes, weights, out):
    """out[v] = sum_j weights[v, j] * positions[tet_nodes[v, j]] for every embedded vertex v.

    positions (N,3) m node positions; tet_nodes (V,4) int node indices; weights (V,4); out (V,3) m.
    """
    for v in range(tet_nodes.shape[0]):
        a, b, c, d = tet_nodes[v, 0], tet_nodes[v, 1], tet_nodes[v, 2], tet_nodes[v, 3]
        wa, wb, wc, wd = weights[v, 0], weights[v, 1], weights[v, 2], weights[v, 3]
        for k in range(3):
            out[v, k] = (wa * positions[a, k] + wb * positions[b, k] + wc * positions[c, k]
                         + wd * positions[d, k])


def barycentric(points, nodes, tets, tet_index) -> np.ndarray:
    """(P,4) barycentric coordinates of ``points`` (P,3) in tets ``tets[tet_index]`` (may be < 0 or > 1)."""
    p0 = nodes[tets[tet_index, 0]]
    mats = np.stack([nodes[tets[tet_index, j]] - p0 for j in (1, 2, 3)], axis=2)   # (P,3,3) columns
    lam = np.linalg.solve(mats, (points - p0)[:, :, None])[:, :, 0]
    return np.concatenate([1.0 - lam.sum(axis=1, keepdims=True), lam], axis=1)


@dataclass
class Embedding:
    """Vertices tied to tets: ``tet_index`` (V,), ``tet_nodes`` (V,4) int64 node indices,
    ``weights`` (V,4) barycentric coordinates (sum 1), ``clamped`` (V,) bool (extrapolation was
    clamped; such a vertex is not reproduced exactly at rest), ``inside`` (V,) bool (in its tet)."""

    tet_index: np.ndarray
    tet_nodes: np.ndarray
    weights: np.ndarray
    inside: np.ndarray
    clamped: np.ndarray

    @property
    def n_vertices(self) -> int:
        return len(self.tet_index)

    def positions(self, node_positions, out=None) -> np.ndarray:
        """(V,3) m embedded vertex positions for the node positions (N,3) m (into ``out`` if given)."""
        x = np.ascontiguousarray(node_positions, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != 3 or (len(self.tet_nodes) and x.shape[0] <= self.tet_nodes.max()):
            raise ConfigError(f"node positions must be (N, 3) m covering the embedding's tets, got shape {x.shape}")
        if out is None:
            out = np.empty((self.n_vertices, 3))
        interpolate(x, self.tet_nodes, self.weights, out)
        return out


def embed_points(points, nodes, tets, max_extrapolation: float = MAX_EXTRAPOLATION,
                 n_candidates: int = N_CANDIDATES) -> Embedding:
    """Embed ``points`` (V,3) m in the tet mesh (``nodes`` (N,3) m, ``tets`` (T,4)).

    Each point gets the tet among its ``n_candidates`` nearest (by centroid) whose smallest
    barycentric coordinate is largest: the containing tet if there is one, else the tet it is
    least outside of; coordinates outside ``[-max_extrapolation, 1 + max_extrapolation]`` are clamped.
    """
    from scipy.spatial import cKDTree

    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0 or not np.all(np.isfinite(pts)):
        raise ConfigError(f"points to embed must be a non-empty finite (V, 3) array in m, got shape {pts.shape}")
    nodes = np.ascontiguousarray(nodes, dtype=np.float64)
    tets = np.ascontiguousarray(tets, dtype=np.int64).reshape(-1, 4)
    if len(tets) == 0:
        raise ConfigError("cannot embed in a volume without tets (surface-only volumes have none)")
    if not (isinstance(max_extrapolation, (int, float)) and max_extrapolation >= 0):
        raise ConfigError(f"max_extrapolation must be >= 0 (in tet sizes), got {max_extrapolation!r}")
    validate.integer(n_candidates, "n_candidates", lo=1, fix="the number of nearest tets tried per point, e.g. 8")
    k = int(min(n_candidates, len(tets)))
    centroids = nodes[tets].mean(axis=1)
    _, cand = cKDTree(centroids).query(pts, k=k)
    cand = np.asarray(cand).reshape(len(pts), k)
    best = np.full(len(pts), -np.inf)
    tet_index = np.zeros(len(pts), dtype=np.int64)
    weights = np.zeros((len(pts), 4))
    for j in range(k):
        w = barycentric(pts, nodes, tets, cand[:, j])
        score = w.min(axis=1)
        better = score > best
        best[better] = score[better]
        tet_index[better] = cand[better, j]
        weights[better] = w[better]
    inside = best >= -1e-9
    lo, hi = -float(max_extrapolation), 1.0 + float(max_extrapolation)
    clamped = np.any((weights < lo) | (weights > hi), axis=1)
    if clamped.any():
        w = np.clip(weights[clamped], lo, hi)
        weights[clamped] = w / w.sum(axis=1, keepdims=True)
    return Embedding(tet_index, np.ascontiguousarray(tets[tet_index]), np.ascontiguousarray(weights), inside, clamped)


def embed_surface(vertices, volume, **kwargs) -> Embedding:
    """Embed the vertices (V,3) m of a visual surface in ``volume`` (a :class:`Volume`); see
    :func:`embed_points` for the options."""
    return embed_points(vertices, volume.nodes, volume.tets, **kwargs)
