"""Warp kernels of a spherical inclusion's per-tet Young's factors, for the worlds being reset: the
arithmetic of :func:`surgsim_envs.envs.tissue_setup.inclusion_young_factors` on the device, so a
reset uploads a few numbers per world (centre, radius, contrast, scale) instead of computing (T,)
factors per world on the host.

* :func:`sphere_fractions` - one thread per (reset world, tet): the share of the tet's volume inside
  the sphere as :func:`surgsim_envs.geometry.sphere_fraction.sphere_volume_fractions` computes it
  (1 if every corner lies inside, 0 if the tet's bounding sphere misses it, else the share of the
  same ``n^3`` equal-volume sample points inside);
* :func:`nearest_share` - one thread per reset world: a sphere too small for the sampling to see
  puts its whole volume (at most the tet's) into the tet whose centroid is nearest (the first such
  tet, as ``np.argmin``);
* :func:`mixed_factors` - one thread per (reset world, tet): ``scale (1 + (contrast - 1) phi)``
  (:func:`surgsim_envs.geometry.sphere_fraction.mixed_young_factors`).

The fractions are counts of sample points, so they equal the host's unless a sample point lies
within rounding of the sphere (the sample coordinates may round differently in the last bit);
the factors then agree to rounding (tests/test_batch_inclusion_factors.py).
"""

from __future__ import annotations

import warp as wp

# forward kernels only: nothing differentiates them, and adjoints would double the compile time
wp.set_module_options({"enable_backward": False})

f64 = wp.float64


@wp.kernel
def sphere_fractions(centre: wp.array(dtype=wp.vec3d), radius: wp.array(dtype=f64),
                     corners: wp.array2d(dtype=wp.vec3d), mid: wp.array(dtype=wp.vec3d), reach: wp.array(dtype=f64),
                     bary: wp.array2d(dtype=f64), frac: wp.array2d(dtype=f64)):
    """``frac[k, t]``: the share of tet t inside sphere k (``centre[k]``, ``radius[k]``, m)."""
    k, t = wp.tid()
    c = centre[k]
    r = radius[k]
    inside = int(1)
    for i in range(4):
        d = corners[t, i] - c
        if wp.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) > r:
            inside = 0
    if inside == 1:
        frac[k, t] = f64(1.0)
        return
    dm = mid[t] - c
    if not (wp.sqrt(dm[0] * dm[0] + dm[1] * dm[1] + dm[2] * dm[2]) < r + reach[t]):
        frac[k, t] = f64(0.0)
        return
    v0 = corners[t, 0]
    v1 = corners[t, 1]
    v2 = corners[t, 2]
    v3 = corners[t, 3]
    r2 = r * r
    count = int(0)
    n = bary.shape[0]
    for s in range(n):
        p = bary[s, 0] * v0 + bary[s, 1] * v1 + bary[s, 2] * v2 + bary[s, 3] * v3 - c
        if (p[0] * p[0] + p[1] * p[1]) + p[2] * p[2] < r2:
            count += 1
    frac[k, t] = f64(count) / f64(n)


@wp.kernel
def nearest_share(centre: wp.array(dtype=wp.vec3d), radius: wp.array(dtype=f64), mid: wp.array(dtype=wp.vec3d),
                  volume: wp.array(dtype=f64), frac: wp.array2d(dtype=f64)):
    """Sphere k seen by no sample point: its volume (at most the tet's) to the nearest tet."""
    k = wp.tid()
    T = frac.shape[1]
    for t in range(T):
        if frac[k, t] > f64(0.0):
            return
    c = centre[k]
    best = int(0)
    best_d = f64(1.0e300)
    for t in range(T):
        dm = mid[t] - c
        d = wp.sqrt(dm[0] * dm[0] + dm[1] * dm[1] + dm[2] * dm[2])
        if d < best_d:
            best_d = d
            best = t
    r = radius[k]
    frac[k, best] = wp.min(f64(1.0), (f64(4.0) / f64(3.0)) * f64(wp.pi) * r * r * r / volume[best])


@wp.kernel
def mixed_factors(frac: wp.array2d(dtype=f64), contrast: wp.array(dtype=f64), scale: wp.array(dtype=f64),
                  factors: wp.array2d(dtype=f64)):
    """``factors[k, t] = scale[k] (1 + (contrast[k] - 1) clip(frac[k, t], 0, 1))``."""
    k, t = wp.tid()
    phi = wp.clamp(frac[k, t], f64(0.0), f64(1.0))
    factors[k, t] = scale[k] * (f64(1.0) + (contrast[k] - f64(1.0)) * phi)
