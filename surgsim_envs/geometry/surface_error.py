"""Signed surface-to-surface distances: the validation procedure of Vandewalle et al. 2003 (section 2.2).

For every vertex p of a *predicted* surface, the closest point q on the *reference* surface and
the distance |p - q|, signed by the reference's exterior normal at q: positive (green in the
paper's maps) where the prediction lies outside the reference, i.e. along its outward normal
("too much material"), negative (red) where it lies inside ("lack of material"). The normal at q
is the barycentric interpolation of the reference's angle-weighted vertex normals, so the sign is
also right where q falls on an edge or a vertex of the reference. The error histogram is then
summarised by its mean mu and standard deviation sigma (the ideal is a Dirac pulse at 0).

Surfaces: (V,3) vertices in m and (F,3) triangles whose right-hand normals point to the exterior
(a :class:`~surgsim_envs.geometry.Volume`'s ``surface`` is). Open surfaces (a skin patch) are fine.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from surgsim_envs.errors import ConfigError


def _check_surface(vertices, faces, what: str):
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0 or not np.all(np.isfinite(v)):
        raise ConfigError(f"{what} vertices must be a finite non-empty (V, 3) array in m, got shape {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0 or not np.issubdtype(f.dtype, np.integer):
        raise ConfigError(f"{what} faces must be a non-empty (F, 3) integer array, got shape {f.shape} {f.dtype}")
    if f.min() < 0 or f.max() >= len(v):
        raise ConfigError(f"{what} faces index vertices outside [0, {len(v)}): [{f.min()}, {f.max()}]")
    return v, f.astype(np.int64)


def signed_surface_distance(points, ref_vertices, ref_faces) -> np.ndarray:
    """(P,) signed closest distance (m) of ``points`` (P,3) to the reference surface (sign: module doc)."""
    import trimesh

    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if not np.all(np.isfinite(pts)):
        raise ConfigError("predicted surface vertices contain NaN/inf")
    v, f = _check_surface(ref_vertices, ref_faces, "reference surface")
    mesh = trimesh.Trimesh(v, f, process=False)
    closest, dist, tri = trimesh.proximity.closest_point(mesh, pts)
    bary = trimesh.triangles.points_to_barycentric(mesh.triangles[tri], closest)
    normals = np.einsum("pk,pkj->pj", bary, mesh.vertex_normals[f[tri]])
    side = np.einsum("pj,pj->p", pts - closest, normals)
    return np.where(side < 0.0, -dist, dist)


@dataclass
class SurfaceError:
    """Per-vertex signed distances (m) of a predicted surface to a reference, and their summary."""

    distances: np.ndarray

    @property
    def mean(self) -> float:
        """mu (m)."""
        return float(np.mean(self.distances))

    @property
    def std(self) -> float:
        """sigma (m)."""
        return float(np.std(self.distances))

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.distances ** 2)))

    def summary(self) -> dict:
        d = self.distances
        return {"vertices": int(len(d)), "mu_m": self.mean, "sigma_m": self.std, "rms_m": self.rms,
                "min_m": float(d.min()), "max_m": float(d.max()),
                "within_1mm": float(np.mean(np.abs(d) <= 1e-3))}


def surface_error(pred_vertices, pred_faces, ref_vertices, ref_faces) -> SurfaceError:
    """:class:`SurfaceError` of a predicted surface against a reference surface: one distance per
    vertex used by ``pred_faces`` (in ascending vertex order), so a model's full node array can be
    passed with its skin triangles."""
    v, f = _check_surface(pred_vertices, pred_faces, "predicted surface")
    return SurfaceError(signed_surface_distance(v[np.unique(f)], ref_vertices, ref_faces))
