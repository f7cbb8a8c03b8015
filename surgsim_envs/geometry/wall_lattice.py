"""Layer-conforming box lattices of a flat layered wall (skin, fat, muscle, peritoneum over a bed).

A wall patch of ``size`` (x, y) m centred on the origin, bed at z = 0, its layers stacked from the
bed up (:func:`layer_planes`), cut into Kuhn cells on three node axes:

* z conforming to the layers: a node on every interface, so that no tet straddles two materials;
  the top layer (the skin) in thin cells (a stiff skin on a soft fat bends as a plate: one linear
  tet through it locks);
* x and y either graded about a press site (:func:`graded_wall_volume`, the converged force
  reference of a press) or uniform (:func:`uniform_wall_volume`, a task's own wall, pressed anywhere).

Each tet is labelled with the index (``planes`` order) of the layer its centroid lies in, plus
``len(planes)`` for the tets whose centroid lies within ``nodule_radius`` of ``nodule_centre``
(an inclusion by the palpation tasks' rule). Units: m.
"""

from __future__ import annotations

import math

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError

#: m, half extent (x and y) of the fine region about a press site of a graded wall: the nodule's
#: radius (8 mm) plus the contact radius of a 5 mm press of the 5 mm probe would need 13 mm; the
#: skin carries the load farther out as a plate, so the fine region reaches 15 mm
FINE_HALF_WIDTH = 0.015
#: m, depth below the skin/fat interface to which the fat keeps the skin's cell size (then it grows)
FINE_FAT_DEPTH = 0.005
#: a graded wall's skin cells are at most this fraction of the fine (x, y) spacing tall
SKIN_CELL_FRACTION = 0.5


def layer_planes(thickness: dict) -> list[tuple[str, float, float]]:
    """(layer, z_bottom, z_top) m from the bed up, for the wall's layer thicknesses (outside in)."""
    out, z = [], 0.0
    for name in reversed(list(thickness)):
        out.append((name, z, z + float(thickness[name])))
        z += float(thickness[name])
    return out


def wall_z_axis(planes, fine: float, coarse: float, ratio: float) -> np.ndarray:
    """Node z (m, ascending) with a node on every layer plane; the top layer (skin) in cells of at
    most ``fine * SKIN_CELL_FRACTION``, the layer under it graded from that size to ``coarse``, the
    others in cells of at most ``coarse``."""
    from surgsim_envs.geometry.graded_axis import graded_axis

    top_cell = fine * SKIN_CELL_FRACTION
    parts = []
    for k, (_, lo, hi) in enumerate(planes):
        if k == len(planes) - 1:
            n = max(1, math.ceil((hi - lo) / top_cell - 1e-9))
            parts.append(np.linspace(lo, hi, n + 1))
        elif k == len(planes) - 2:
            parts.append(graded_axis(lo, hi, hi, min(FINE_FAT_DEPTH, hi - lo), top_cell, coarse, ratio,
                                     what="wall z axis"))
        else:
            n = max(1, math.ceil((hi - lo) / coarse - 1e-9))
            parts.append(np.linspace(lo, hi, n + 1))
    return _joined(parts, planes)


def uniform_wall_z_axis(planes, spacing: float, skin_cell: float) -> np.ndarray:
    """Node z (m, ascending) with a node on every layer plane, each layer in equal cells of at most
    ``spacing``, the top layer (skin) in equal cells of at most ``skin_cell``. Equal cells within a
    layer keep the median height of a layer's tet centroids at the layer's middle."""
    parts = []
    for k, (_, lo, hi) in enumerate(planes):
        cell = skin_cell if k == len(planes) - 1 else spacing
        n = max(1, math.ceil((hi - lo) / cell - 1e-3))
        parts.append(np.linspace(lo, hi, n + 1))
    return _joined(parts, planes)


def _joined(parts, planes) -> np.ndarray:
    z = np.concatenate([p if i == 0 else p[1:] for i, p in enumerate(parts)])
    z[-1] = planes[-1][2]
    return z


def wall_volume_on_axes(x, y, z, planes, nodule_centre=None, nodule_radius: float = 0.0, name: str = "wall"):
    """A :class:`~surgsim_envs.geometry.Volume` of Kuhn cells on node axes ``x``, ``y``, ``z`` (m,
    ascending), tets labelled by layer (and nodule, see the module docstring; none when
    ``nodule_centre`` is None)."""
    from surgsim_envs.geometry.box import lattice_tets
    from surgsim_envs.geometry.volume import Volume, tet_signed_volumes

    grid = np.stack(np.meshgrid(x, y, z, indexing="ij"), axis=-1).reshape(-1, 3)
    tets = lattice_tets((len(x), len(y), len(z)))
    neg = tet_signed_volumes(grid, tets) < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    centroids = grid[tets].mean(axis=1)
    bottoms = np.array([lo for _, lo, _ in planes])
    layer = np.clip(np.searchsorted(bottoms, centroids[:, 2], side="right") - 1, 0, len(planes) - 1)
    if nodule_centre is not None:
        inside = np.linalg.norm(centroids - np.asarray(nodule_centre, dtype=float), axis=1) < float(nodule_radius)
        layer = layer + len(planes) * inside
    return Volume(grid, tets, labels=layer.astype(np.int32), name=name)


def graded_wall_volume(size, planes, site, fine: float, nodule_centre, nodule_radius: float, coarse: float,
                       ratio: float):
    """The lattice of a press at ``site`` (x, y) m: x and y at spacing ``fine`` within
    :data:`FINE_HALF_WIDTH` of it, growing by ``ratio`` per cell to ``coarse``; z by :func:`wall_z_axis`."""
    from surgsim_envs.geometry.graded_axis import graded_axis

    sx, sy = (float(v) for v in size)
    x = graded_axis(-sx / 2, sx / 2, float(site[0]), FINE_HALF_WIDTH, fine, coarse, ratio, what="wall x axis")
    y = graded_axis(-sy / 2, sy / 2, float(site[1]), FINE_HALF_WIDTH, fine, coarse, ratio, what="wall y axis")
    z = wall_z_axis(planes, fine, coarse, ratio)
    return wall_volume_on_axes(x, y, z, planes, nodule_centre, nodule_radius, name="abdominal_wall_reference")


def uniform_wall_volume(size, planes, spacing: float, skin_cell: float, name: str = "abdominal_wall"):
    """A wall patch of ``size`` (x, y) m on a uniform x-y lattice of ``spacing`` m (each side divided
    into equal cells of at most ``spacing``; the centre is a node when a side holds an even number of
    cells), z by :func:`uniform_wall_z_axis`; tets labelled by layer only."""
    spacing = validate.positive(spacing, f"{name}: spacing", unit="m", fix="a lattice spacing, e.g. 0.0025")
    skin_cell = validate.positive(skin_cell, f"{name}: skin cell", unit="m", fix="e.g. 0.001")
    axes = []
    for k, side in enumerate(size):
        side = validate.positive(side, f"{name}: size[{k}]", unit="m", fix="a patch side, e.g. 0.08")
        n = math.ceil(side / spacing - 1e-3)    # a spacing given to a few digits (3.333 mm) still divides
        if n > 4000:
            raise ConfigError(f"{name}: spacing {spacing} m gives {n} cells across {side} m; raise it")
        axes.append(np.linspace(-side / 2, side / 2, n + 1))
    z = uniform_wall_z_axis(planes, spacing, skin_cell)
    return wall_volume_on_axes(axes[0], axes[1], z, planes, name=name)


__all__ = ["FINE_HALF_WIDTH", "FINE_FAT_DEPTH", "SKIN_CELL_FRACTION", "layer_planes", "wall_z_axis",
           "uniform_wall_z_axis", "wall_volume_on_axes", "graded_wall_volume", "uniform_wall_volume"]
