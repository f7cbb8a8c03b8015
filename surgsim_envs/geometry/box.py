"""Structured tetrahedral boxes (tissue blocks and slabs).

Each lattice cell is split into six tetrahedra along its main diagonal (Kuhn/Freudenthal split),
which conforms across cells and gives well-shaped tets.
"""

from __future__ import annotations

import itertools

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.graded_axis import graded_axis
from surgsim_envs.geometry.volume import Volume, tet_signed_volumes

# The 6 Kuhn tets of the unit cube: paths 000 -> 111 adding one axis at a time.
_KUHN = []
for perm in itertools.permutations(range(3)):
    corner = [0, 0, 0]
    path = [tuple(corner)]
    for axis in perm:
        corner[axis] = 1
        path.append(tuple(corner))
    _KUHN.append(path)


def lattice_tets(shape: tuple[int, int, int]) -> np.ndarray:
    """Tets (T, 4) of a node lattice with ``shape`` = nodes per axis (C-order node indexing)."""
    nx, ny, nz = shape
    idx = np.arange(nx * ny * nz).reshape(nx, ny, nz)
    cx, cy, cz = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), np.arange(nz - 1), indexing="ij")
    cx, cy, cz = cx.ravel(), cy.ravel(), cz.ravel()
    tets = []
    for path in _KUHN:
        tets.append(np.stack([idx[cx + a, cy + b, cz + c] for (a, b, c) in path], axis=1))
    return np.concatenate(tets, axis=0).astype(np.int32)


def box_volume(size=(0.08, 0.08, 0.03), spacing: float = 0.005, center=(0.0, 0.0, 0.0),
               name: str = "block", grading=None) -> Volume:
    """A box of ``size`` (m, x/y/z) with nodes about ``spacing`` (m) apart, centred at ``center``.

    The bottom face lies at ``center[2] - size[2] / 2``. ``grading`` (optional mapping): a lattice
    fine around a point and ``spacing`` (the coarse spacing) elsewhere, same Kuhn cells on graded
    per-axis coordinates (:mod:`surgsim_envs.geometry.graded_axis`); keys ``fine`` (m, the spacing
    near the point), ``around`` ((3,) m, the point, a node; in the box's own frame, as ``center``),
    ``half_widths`` ((3,) m, the fine region's half extents about it) and optional ``ratio``
    (growth per cell, default 1.3).
    """
    size = np.asarray(size, dtype=float)
    if size.shape != (3,) or np.any(size <= 0) or not np.all(np.isfinite(size)):
        raise ConfigError(f"box size must be three positive lengths in m, got {size.tolist()}")
    if not (np.isfinite(spacing) and spacing > 0):
        raise ConfigError(f"spacing must be > 0 m, got {spacing!r}; try 0.005 (5 mm)")
    if grading is None:
        counts = np.maximum(np.round(size / spacing).astype(int), 1) + 1
        axes = [np.linspace(-s / 2, s / 2, n) + c for s, n, c in zip(size, counts, center)]
    else:
        axes = graded_axes(size, spacing, center, grading)
        counts = np.array([len(a) for a in axes])
    if counts.prod() > 2_000_000:
        raise ConfigError(f"spacing {spacing} m gives {counts.prod()} nodes for box {size.tolist()}; increase spacing")
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    tets = lattice_tets(tuple(counts))
    vol = tet_signed_volumes(grid, tets)
    neg = vol < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    return Volume(grid, tets, name=name)


GRADING_KEYS = ("fine", "around", "half_widths", "ratio")


def graded_axes(size, coarse: float, center, grading) -> list[np.ndarray]:
    """The three node coordinate arrays (m) of a graded box (``box_volume``'s ``grading``)."""
    if not hasattr(grading, "keys"):
        raise ConfigError(f"grading must be a mapping with keys {list(GRADING_KEYS)}, got {type(grading).__name__}")
    unknown = sorted(set(grading) - set(GRADING_KEYS))
    missing = [k for k in ("fine", "around", "half_widths") if k not in grading]
    if unknown or missing:
        raise ConfigError(f"grading: unknown keys {unknown}, missing {missing}; keys: fine (m), around ((3,) m), "
                          "half_widths ((3,) m), ratio (optional, default 1.3)")
    vectors = {}
    for key in ("around", "half_widths"):
        v = np.asarray(grading[key], dtype=float) if not isinstance(grading[key], str) else np.zeros(0)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise ConfigError(f"grading[{key!r}] must be three finite lengths in m (x, y, z), got {grading[key]!r}")
        vectors[key] = v
    ratio = grading.get("ratio", 1.3)
    return [graded_axis(c - s / 2, c + s / 2, a, w, grading["fine"], coarse, ratio, what=f"grading axis {ax}")
            for ax, s, c, a, w in zip("xyz", size, center, vectors["around"], vectors["half_widths"])]
