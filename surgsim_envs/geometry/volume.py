"""The volumetric mesh every tissue model is built from.

A :class:`Volume` is a tetrahedral mesh (nodes in metres) with its outward-oriented boundary
triangles and an integer region label per tetrahedron (0 = bulk; other labels mark inclusions or
layers, so that heterogeneous materials are just per-element fields). Surface-only models use
``nodes`` + ``surface`` and may ignore ``tets``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from surgsim_envs.errors import ConfigError


def tet_signed_volumes(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volume (m^3) of each tet; positive for the (0,1,2,3) right-handed ordering."""
    p0, p1, p2, p3 = (nodes[tets[:, i]] for i in range(4))
    return np.einsum("ij,ij->i", p1 - p0, np.cross(p2 - p0, p3 - p0)) / 6.0


def boundary_triangles(tets: np.ndarray) -> np.ndarray:
    """Faces used by exactly one tet, oriented outward (right-hand normal points out)."""
    tets = np.asarray(tets)
    # faces opposite to vertex 0..3, each ordered so the normal points away from that vertex
    # for a positively oriented tet.
    faces = np.concatenate(
        [tets[:, [1, 2, 3]], tets[:, [0, 3, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 1]]], axis=0
    )
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    return faces[counts[inverse] == 1].astype(np.int32)


@dataclass
class Volume:
    """Tetrahedral volume (SI units).

    nodes: (N, 3) float64 rest positions, m.
    tets: (T, 4) int32, positively oriented (signed volume > 0).
    surface: (F, 3) int32 boundary triangles, outward normals.
    labels: (T,) int32 region label per tet (0 = bulk).
    name: human-readable name (e.g. "spleen").
    node_labels: optional (N,) int32 per-node region label (max over incident tets by default).
    """

    nodes: np.ndarray
    tets: np.ndarray
    surface: np.ndarray | None = None
    labels: np.ndarray | None = None
    name: str = "volume"
    node_labels: np.ndarray | None = field(default=None)

    def __post_init__(self) -> None:
        self.nodes = np.ascontiguousarray(self.nodes, dtype=np.float64)
        if self.nodes.ndim != 2 or self.nodes.shape[1] != 3 or len(self.nodes) == 0:
            raise ConfigError(f"volume '{self.name}': nodes must be a non-empty (N, 3) array, got shape {self.nodes.shape}")
        if not np.all(np.isfinite(self.nodes)):
            raise ConfigError(f"volume '{self.name}': nodes contain NaN/inf; clean the mesh")
        self.tets = np.ascontiguousarray(self.tets, dtype=np.int32).reshape(-1, 4)
        n = len(self.nodes)
        if len(self.tets) and (self.tets.min() < 0 or self.tets.max() >= n):
            raise ConfigError(f"volume '{self.name}': tet indices must lie in [0, {n}), got [{self.tets.min()}, {self.tets.max()}]")
        if self.surface is None:
            if len(self.tets) == 0:
                raise ConfigError(f"volume '{self.name}': give tets or a surface")
            self.surface = boundary_triangles(self.tets)
        self.surface = np.ascontiguousarray(self.surface, dtype=np.int32).reshape(-1, 3)
        if self.labels is None:
            self.labels = np.zeros(len(self.tets), dtype=np.int32)
        self.labels = np.ascontiguousarray(self.labels, dtype=np.int32)
        if self.labels.shape != (len(self.tets),):
            raise ConfigError(f"volume '{self.name}': labels must have shape ({len(self.tets)},), got {self.labels.shape}")
        if self.node_labels is None:
            nl = np.zeros(n, dtype=np.int32)
            if len(self.tets):
                np.maximum.at(nl, self.tets.reshape(-1), np.repeat(self.labels, 4))
            self.node_labels = nl

    def __repr__(self) -> str:   # short: a Volume in an error message must not print its arrays
        lo, hi = self.bounds()
        return (f"<Volume '{self.name}' {len(self.nodes)} nodes, {len(self.tets)} tets, {len(self.surface)} surface "
                f"triangles, extent {np.round(hi - lo, 4).tolist()} m>")

    # Derived quantities -----------------------------------------------------------------------
    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    @property
    def surface_nodes(self) -> np.ndarray:
        """Sorted unique indices of nodes on the boundary surface."""
        return np.unique(self.surface)

    def tet_volumes(self) -> np.ndarray:
        return tet_signed_volumes(self.nodes, self.tets)

    def total_volume(self) -> float:
        return float(self.tet_volumes().sum())

    def edges(self) -> np.ndarray:
        """(E, 2) unique undirected edges of the tets (or of the surface if there are no tets)."""
        if len(self.tets):
            pairs = np.stack([self.tets[:, [0, 0, 0, 1, 1, 2]].ravel(), self.tets[:, [1, 2, 3, 2, 3, 3]].ravel()], axis=1)
        else:
            pairs = np.concatenate([self.surface[:, [0, 1]], self.surface[:, [1, 2]], self.surface[:, [2, 0]]])
        pairs = np.sort(pairs, axis=1)
        return np.unique(pairs, axis=0).astype(np.int32)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.nodes.min(axis=0), self.nodes.max(axis=0)

    def translated(self, offset) -> "Volume":
        """Copy moved by ``offset`` (m)."""
        return Volume(self.nodes + np.asarray(offset, dtype=float), self.tets.copy(), self.surface.copy(),
                      self.labels.copy(), self.name, self.node_labels.copy())

    def check(self, min_quality: float = 0.0) -> None:
        """Raise ConfigError on inverted or degenerate tets (signed volume <= tiny)."""
        vol = self.tet_volumes()
        if len(vol) == 0:
            return
        scale = np.ptp(self.nodes, axis=0).max() ** 3
        bad = np.flatnonzero(vol <= 1e-12 * scale)
        if len(bad):
            raise ConfigError(
                f"volume '{self.name}': {len(bad)} degenerate or inverted tets (first: #{bad[0]}, "
                f"volume {vol[bad[0]]:.3g} m^3); reorder their nodes or remesh at a different spacing"
            )
