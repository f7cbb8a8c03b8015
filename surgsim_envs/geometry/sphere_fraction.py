"""The fraction of each element's volume that lies inside a sphere.

A spherical inclusion does not follow the lattice: its surface cuts through elements. Stiffening
only the elements whose centroid lies inside (the rule of :mod:`surgsim_envs.geometry.inclusion`)
rounds the inclusion to whole elements, so its stiff volume and its depth change in steps as the
lattice or the inclusion moves (a 7 mm lump stiffens whole 10 mm tets), and the forces above it
converge only at first order under refinement. The volume fraction makes the inclusion's volume
right on every lattice; a task mixes the two materials by it (:func:`mixed_young_factors`).

How it is computed: an element wholly inside the sphere (every corner inside; a sphere is convex)
has fraction 1, one whose bounding sphere misses it 0; an element the surface cuts is sampled at
``n^3`` points spread evenly over it (a low-discrepancy sequence in the unit cube, mapped onto the
tetrahedron by sorting each point's coordinates: a measure-preserving map, so every point carries
the same volume). With the default ``n = 10`` (1,000 points) a cut element's fraction is within 0.012 of
its exact value (a tetrahedron cut by planes parallel and oblique to its faces, tested; 0.031 with
216 points). Cost (median over random spheres of radius 3-12 mm in a 10 x 10 x 2 cm slab): 1.0 ms
for its 1,200 tets at 10 mm, 4.3 ms for 9,600 at 5 mm, 74 ms for 150,000 at 2 mm (the sample
points by one batched matrix product; the distances summed in the order of ``np.sum``).
"""

from __future__ import annotations

import math

import numpy as np

from surgsim_envs.errors import ConfigError

#: points per axis of the sampling grid in a cut element (n^3 points)
SAMPLES_PER_AXIS = 10
#: elements sampled per chunk (bounds the work arrays to ~ chunk x n^3 x 3 floats)
_CHUNK = 2048


def simplex_sample_points(count: int) -> np.ndarray:
    """(count, 4) barycentric coordinates of ``count`` equal-volume points spread over a tetrahedron:
    the first points of Roberts' R3 low-discrepancy sequence in the unit cube, mapped onto the
    tetrahedron by sorting their coordinates. (A regular grid would alias: its sorted points fall on
    a few planes parallel to the faces, and a cut parallel to a face saw only those levels.)"""
    g = 1.2207440846057596          # the plastic number: x^3 = x + 1
    alpha = np.array([1.0 / g, 1.0 / g ** 2, 1.0 / g ** 3])
    u = np.mod(0.5 + np.arange(1, count + 1)[:, None] * alpha[None, :], 1.0)
    s = np.sort(u, axis=1)
    return np.stack([s[:, 0], s[:, 1] - s[:, 0], s[:, 2] - s[:, 1], 1.0 - s[:, 2]], axis=1)


def sphere_volume_fractions(vertices, centre, radius: float, samples_per_axis: int = SAMPLES_PER_AXIS) -> np.ndarray:
    """(T,) fraction in [0, 1] of each element's volume inside the sphere (``centre`` (3,) m,
    ``radius`` m). ``vertices`` (T, 4, 3) m are the corners of tetrahedra; (T, 1, 3) are point
    elements (a surface-only model's nodes), whose fraction is 1 inside and 0 outside."""
    v = np.asarray(vertices, dtype=float)
    if v.ndim != 3 or v.shape[2] != 3 or v.shape[1] not in (1, 4):
        raise ConfigError(f"sphere_volume_fractions: vertices must be (T, 4, 3) or (T, 1, 3) m, got shape {v.shape}")
    c = np.asarray(centre, dtype=float).reshape(-1)
    if c.shape != (3,) or not np.all(np.isfinite(c)):
        raise ConfigError(f"sphere_volume_fractions: centre must be three finite coordinates in m, got {centre!r}")
    r = float(radius)
    if not (math.isfinite(r) and r > 0):
        raise ConfigError(f"sphere_volume_fractions: radius must be > 0 m, got {radius!r}")
    n = int(samples_per_axis)
    if n < 1:
        raise ConfigError(f"sphere_volume_fractions: samples_per_axis must be >= 1, got {samples_per_axis!r}")
    corner = np.linalg.norm(v - c, axis=2)                        # (T, k) corner distances
    frac = np.zeros(len(v))
    if v.shape[1] == 1:
        frac[corner[:, 0] < r] = 1.0
        return frac
    frac[np.all(corner <= r, axis=1)] = 1.0
    mid = v.mean(axis=1)
    reach = np.linalg.norm(v - mid[:, None, :], axis=2).max(axis=1)
    cut = np.flatnonzero((np.linalg.norm(mid - c, axis=1) < r + reach) & (frac < 1.0))
    bary = simplex_sample_points(n ** 3)
    for start in range(0, len(cut), _CHUNK):
        idx = cut[start:start + _CHUNK]
        pts = np.matmul(bary[None], v[idx])                          # (t, n^3, 3): BLAS, not einsum's loop
        pts -= c
        np.square(pts, out=pts)
        dist2 = pts[..., 0] + pts[..., 1]                           # summed in np.sum's order: the same bits
        dist2 += pts[..., 2]
        frac[idx] = np.count_nonzero(dist2 < r * r, axis=1) / bary.shape[0]
    return frac


def mixed_young_factors(fractions, contrast: float, scale: float = 1.0) -> np.ndarray:
    """(T,) Young's modulus factors of elements holding ``fractions`` of an inclusion ``contrast`` x
    stiffer than the rest, the whole scaled by ``scale``: ``scale (1 + (contrast - 1) phi)``, the
    volume-weighted mean of the two moduli (the rule of mixtures, Voigt's bound: the cut element
    is as stiff as its parts side by side; exact for whole elements and the choice that keeps the
    inclusion's stiffness-weighted volume right on every lattice)."""
    phi = np.clip(np.asarray(fractions, dtype=float), 0.0, 1.0)
    return float(scale) * (1.0 + (float(contrast) - 1.0) * phi)
