"""Material regions: mark tets of an inclusion with a region label.

Heterogeneous tissue (Lin et al. 2008) is a volume whose tets carry region labels; a tissue model maps
each label to a material (``region_materials={1: "tumour"}``). A tet belongs to the inclusion when
its centroid lies inside the inclusion's shape.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.volume import Volume


def tet_centroids(volume: Volume) -> np.ndarray:
    """(T, 3) centroids of the tets, m."""
    return volume.nodes[volume.tets].mean(axis=1)


def add_spherical_inclusion(volume: Volume, centre, radius: float, label: int = 1) -> Volume:
    """Copy of ``volume`` whose tets with centroid inside the sphere (``centre`` (3,) m, ``radius`` m)
    get region ``label`` (other labels are kept). Raises ConfigError if no tet centroid is inside."""
    if not isinstance(volume, Volume):
        raise ConfigError(f"volume must be a surgsim_envs.geometry.Volume, got {type(volume).__name__}")
    c = np.asarray(centre, dtype=float)
    if c.shape != (3,) or not np.all(np.isfinite(c)):
        raise ConfigError(f"inclusion centre must be three finite coordinates in m, got {centre!r}")
    try:
        r = float(radius)
    except (TypeError, ValueError):
        raise ConfigError(f"inclusion radius must be a length in m, got {radius!r}") from None
    if not (np.isfinite(r) and r > 0):
        raise ConfigError(f"inclusion radius must be > 0 m, got {radius!r}; e.g. 0.005 (5 mm)")
    if not isinstance(label, (int, np.integer)) or isinstance(label, bool) or label < 0:
        raise ConfigError(f"inclusion label must be a non-negative integer, got {label!r}; use 1 for the first inclusion")
    inside = np.linalg.norm(tet_centroids(volume) - c, axis=1) < r
    if not inside.any():
        lo, hi = volume.bounds()
        raise ConfigError(
            f"spherical inclusion (centre {c.round(4).tolist()} m, radius {r:g} m) contains no tet centroid of "
            f"volume '{volume.name}' (bounds {lo.round(4).tolist()} .. {hi.round(4).tolist()} m); "
            "move the centre inside the volume, enlarge the radius or use a finer spacing"
        )
    labels = volume.labels.copy()
    labels[inside] = int(label)
    return Volume(volume.nodes.copy(), volume.tets.copy(), volume.surface.copy(), labels, volume.name)
