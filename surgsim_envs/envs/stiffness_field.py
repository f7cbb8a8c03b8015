"""Re-randomise the stiffness of a built tissue without rebuilding it (any registered model).

A thin helper over the tissue contract v2: per-element Young's modulus factors go to
``model.scale_material("young", factor)`` and masks come from ``model.element_centroids()``, so
every model that lists "young" in its ``material_fields`` serves (mass_spring re-derives its
spring constants, fem its element stiffness and factorisations). Kept for the tasks until they
call ``scale_material`` directly.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.errors import ConfigError


class StiffnessField:
    """Per-element Young's modulus scaling of a :class:`~surgsim_envs.tissue.base.TissueModel`.

    tissue: a built model (its material at build is the reference, factor 1).
    """

    def __init__(self, tissue):
        if "young" not in getattr(tissue, "material_fields", ()):
            raise ConfigError(f"StiffnessField: tissue model '{getattr(tissue, 'name', type(tissue).__name__)}' "
                              "cannot change Young's modulus after build (no 'young' in its material_fields)")
        self.tissue = tissue
        self.centroids = tissue.element_centroids()       # (T,3) m, rest frame
        self.tet_scale = np.ones(len(self.centroids))

    def sphere_mask(self, centre, radius: float) -> np.ndarray:
        """Elements whose rest centroid lies within ``radius`` (m) of ``centre`` (3,) m; at least the nearest one."""
        d = np.linalg.norm(self.centroids - np.asarray(centre, dtype=float)[None], axis=1)
        mask = d < radius
        if not mask.any():
            mask[np.argmin(d)] = True
        return mask

    def apply(self, tet_scale: np.ndarray) -> None:
        """Scale each element's Young's modulus by ``tet_scale`` (T,) (> 0) relative to the build."""
        s = np.asarray(tet_scale, dtype=np.float64)
        if s.shape != self.tet_scale.shape or not np.all(np.isfinite(s)) or np.any(s <= 0):
            raise ConfigError(f"tet_scale must be a positive finite ({len(self.tet_scale)},) array")
        self.tissue.scale_material("young", s)
        self.tet_scale = s.copy()
