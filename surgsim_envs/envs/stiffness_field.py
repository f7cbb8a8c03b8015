"""Re-randomise the stiffness of a built mass-spring tissue without rebuilding it.

The mass-spring model derives each spring's constants from the Young's moduli of the tets around
its edge, ``k_e = sum_t E_t V_t / L0^2`` (see :mod:`surgsim_envs.tissue.mass_spring`). When only
Young's modulus changes (same density, relaxation and nonlinearity), every spring constant (K1,
K2, the Maxwell spring kM and its dashpot b1) scales by ``sum_t E_t V_t / sum_t E0_t V_t``, and
the relaxation times stay the same. :class:`StiffnessField` applies such a per-tet modulus
pattern (a spherical inclusion, a global scale) in microseconds, so ``reset`` needs no rebuild.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.errors import ConfigError


class StiffnessField:
    """Per-tet Young's modulus scaling of a :class:`~surgsim_envs.tissue.mass_spring.MassSpringModel`.

    tissue: a built mass-spring model (its current constants are the reference, factor 1).
    """

    def __init__(self, tissue):
        for attr in ("K1", "K2", "kM", "b1", "springs", "volume"):
            if not hasattr(tissue, attr):
                raise ConfigError(f"StiffnessField needs a mass_spring tissue model, got {type(tissue).__name__} "
                                  f"(no attribute {attr!r}); use TissueConfig(model='mass_spring')")
        self.tissue = tissue
        vol = tissue.volume
        n = tissue.n_nodes
        tets = vol.tets.astype(np.int64)
        edges = tissue.springs
        pairs = np.sort(np.stack([tets[:, [0, 0, 0, 1, 1, 2]].ravel(), tets[:, [1, 2, 3, 2, 3, 3]].ravel()], axis=1),
                        axis=1)
        self._edge_of = np.searchsorted(edges[:, 0] * n + edges[:, 1], pairs[:, 0] * n + pairs[:, 1])
        self._tet_ev = tissue.fields["young"] * vol.tet_volumes()       # E0_t V_t (N m)
        self._w0 = np.bincount(self._edge_of, weights=np.repeat(self._tet_ev, 6), minlength=len(edges))
        self.centroids = tissue.rest_positions[tets].mean(axis=1)       # (T,3) m, rest frame
        self._ref = {k: np.array(getattr(tissue, k), dtype=np.float64) for k in ("K1", "K2", "kM", "b1")}
        self.tet_scale = np.ones(len(tets))

    def sphere_mask(self, centre, radius: float) -> np.ndarray:
        """Tets whose rest centroid lies within ``radius`` (m) of ``centre`` (3,) m; at least the nearest one."""
        d = np.linalg.norm(self.centroids - np.asarray(centre, dtype=float)[None], axis=1)
        mask = d < radius
        if not mask.any():
            mask[np.argmin(d)] = True
        return mask

    def apply(self, tet_scale: np.ndarray) -> None:
        """Scale each tet's Young's modulus by ``tet_scale`` (T,) (> 0) relative to the build."""
        s = np.asarray(tet_scale, dtype=np.float64)
        if s.shape != self.tet_scale.shape or not np.all(np.isfinite(s)) or np.any(s <= 0):
            raise ConfigError(f"tet_scale must be a positive finite ({len(self.tet_scale)},) array")
        self.tet_scale = s.copy()
        w = np.bincount(self._edge_of, weights=np.repeat(self._tet_ev * s, 6), minlength=len(self._w0))
        factor = w / self._w0
        t = self.tissue
        for key, ref in self._ref.items():
            getattr(t, key)[:] = ref * factor
        # the model caches the Maxwell coefficients (kM * ratio) per step size: invalidate them
        cache = getattr(t, "_coeff_cache", None)
        if cache is not None:
            cache.clear()


class ContractStiffnessField:
    """The same interface for any tissue model with the contract-v2 material API
    (``element_centroids()``, ``scale_material("young", factor)``): per-element factors relative
    to the build (for a surface-only model, its nodes are the elements)."""

    def __init__(self, tissue):
        for attr in ("element_centroids", "scale_material"):
            if not hasattr(tissue, attr):
                raise ConfigError(f"{type(tissue).__name__} has no {attr}(); it cannot take a stiffness pattern")
        self.tissue = tissue
        self.centroids = np.asarray(tissue.element_centroids(), dtype=np.float64)
        self.tet_scale = np.ones(len(self.centroids))

    sphere_mask = StiffnessField.sphere_mask

    def apply(self, tet_scale: np.ndarray) -> None:
        s = np.asarray(tet_scale, dtype=np.float64)
        if s.shape != self.tet_scale.shape or not np.all(np.isfinite(s)) or np.any(s <= 0):
            raise ConfigError(f"tet_scale must be a positive finite ({len(self.tet_scale)},) array")
        self.tet_scale = s.copy()
        self.tissue.scale_material("young", s)


def stiffness_field(tissue):
    """A stiffness pattern for ``tissue``: the contract-v2 path if the model has it, else the
    mass-spring fast path."""
    if hasattr(tissue, "scale_material"):
        return ContractStiffnessField(tissue)
    return StiffnessField(tissue)
