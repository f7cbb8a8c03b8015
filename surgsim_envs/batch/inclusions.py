"""Per-tet Young's factors of spherical inclusions computed on the device for the worlds being reset
(:class:`SphereInclusionFactors`, kernels in :mod:`surgsim_envs.batch.inclusion_kernels`).

The single env computes its lump with :func:`surgsim_envs.envs.tissue_setup.inclusion_young_factors`
on the host; a batched reset of k worlds uploads their k centres, radii, contrasts and scales and
gets the (k, T) factors on the device, ready for :meth:`BatchSimulation.set_young_factor_array`.
The tet geometry (corners, centroids, bounding radii, volumes) and the sample points are uploaded
once.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.batch import inclusion_kernels as ik
from surgsim_envs.geometry.sphere_fraction import SAMPLES_PER_AXIS, simplex_sample_points


class SphereInclusionFactors:
    """Young's factors of one sphere per world on the tets of ``vertices`` (T, 4, 3) m, on Warp
    device ``device``."""

    def __init__(self, vertices, device: str):
        import warp as wp

        v = np.asarray(vertices, dtype=np.float64)
        mid = v.mean(axis=1)
        reach = np.linalg.norm(v - mid[:, None, :], axis=2).max(axis=1)
        e = v[:, 1:] - v[:, :1]
        volume = np.abs(np.linalg.det(e)) / 6.0
        self.n_tets = len(v)
        self.device = device
        self._wp = wp
        with wp.ScopedDevice(device):
            self.corners = wp.array(np.ascontiguousarray(v), dtype=wp.vec3d)
            self.mid = wp.array(np.ascontiguousarray(mid), dtype=wp.vec3d)
            self.reach = wp.array(reach, dtype=wp.float64)
            self.volume = wp.array(volume, dtype=wp.float64)
            self.bary = wp.array(simplex_sample_points(SAMPLES_PER_AXIS ** 3), dtype=wp.float64)

    def factors(self, centres, radii, contrasts, scales):
        """(k, T) float64 Warp array: ``scale (1 + (contrast - 1) phi)`` per tet, phi the share of the
        tet inside sphere k (``centres`` (k, 3) m, ``radii`` (k,) m), as the single env's
        ``inclusion_young_factors``."""
        wp = self._wp
        c = np.ascontiguousarray(np.asarray(centres, dtype=np.float64).reshape(-1, 3))
        k, T = len(c), self.n_tets
        with wp.ScopedDevice(self.device):
            centre = wp.array(c, dtype=wp.vec3d)
            radius = wp.array(np.asarray(radii, dtype=np.float64).reshape(k), dtype=wp.float64)
            frac = wp.empty((k, T), dtype=wp.float64)
            out = wp.empty((k, T), dtype=wp.float64)
            if k:
                wp.launch(ik.sphere_fractions, dim=(k, T),
                          inputs=[centre, radius, self.corners, self.mid, self.reach, self.bary, frac])
                wp.launch(ik.nearest_share, dim=k, inputs=[centre, radius, self.mid, self.volume, frac])
                wp.launch(ik.mixed_factors, dim=(k, T),
                          inputs=[frac, wp.array(np.asarray(contrasts, dtype=np.float64).reshape(k), dtype=wp.float64),
                                  wp.array(np.asarray(scales, dtype=np.float64).reshape(k), dtype=wp.float64), out])
        return out
