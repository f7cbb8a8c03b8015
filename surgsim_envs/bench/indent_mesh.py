"""Graded tet meshes of an indentation slab: fine under the indenter, coarser away from it.

The slab is a tensor-product lattice (Kuhn split, like :func:`surgsim_envs.geometry.box_volume`)
whose cells are ``spacing`` wide inside the contact zone and grow geometrically by ``grading``
per cell beyond it, up to ``max_cell``. A quarter of the slab (x >= 0, y >= 0, the indenter on the
z axis) is enough for a centred spherical indenter when the symmetry planes carry roller
conditions; :func:`graded_slab` builds either. Units: m.
"""

from __future__ import annotations


import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.box import lattice_tets
from surgsim_envs.geometry.volume import Volume, tet_signed_volumes


def graded_axis(length: float, fine: float, fine_extent: float, grading: float, max_cell: float) -> np.ndarray:
    """Node coordinates from 0 to ``length`` (m): cells of ``fine`` up to ``fine_extent``, then each
    ``grading`` times the previous (capped at ``max_cell``). The last cell is merged if tiny."""
    if not (fine > 0 and length > 0 and grading >= 1.0 and max_cell >= fine):
        raise ConfigError(f"graded axis needs length > 0, spacing > 0, grading >= 1, max_cell >= spacing; got "
                          f"length={length}, spacing={fine}, grading={grading}, max_cell={max_cell}")
    xs = [0.0]
    h = fine
    while xs[-1] < length - 1e-12:
        if xs[-1] >= fine_extent - 1e-12:
            h = min(h * grading, max_cell)
        xs.append(xs[-1] + h)
    xs = np.array(xs)
    if len(xs) > 2 and (xs[-1] - length) > 0.5 * (xs[-1] - xs[-2]):
        xs = xs[:-1]
    xs[-1] = length
    if len(xs) < 2:
        xs = np.array([0.0, length])
    return xs


def graded_slab(width: float, thickness: float, spacing: float, fine_extent: float, *, grading: float = 1.3,
                max_cell: float | None = None, quarter: bool = True) -> Volume:
    """Square slab ``width`` x ``width`` x ``thickness`` (m), top face at z = 0, bottom at -thickness,
    centred on the z axis; fine cells (``spacing``) within ``fine_extent`` of the axis and of the top.

    quarter: build only x >= 0, y >= 0 (use with symmetry conditions on x = 0 and y = 0).
    """
    validate.positives(width=width, thickness=thickness, spacing=spacing, fine_extent=fine_extent, unit="m",
                       fix="give a positive length in m")
    if spacing > min(width / 2, thickness):
        raise ConfigError(f"spacing {spacing} m is larger than the slab (width {width} m, thickness {thickness} m); "
                          "use a spacing a few times smaller than the thickness")
    max_cell = max(max_cell if max_cell is not None else 8.0 * spacing, spacing)
    half = graded_axis(width / 2, spacing, fine_extent, grading, max_cell)
    lateral = half if quarter else np.concatenate([-half[:0:-1], half])
    depth = graded_axis(thickness, spacing, fine_extent, grading, max_cell)
    zs = -depth[::-1]
    counts = (len(lateral), len(lateral), len(zs))
    if np.prod(counts) > 400_000:
        raise ConfigError(f"graded slab would have {int(np.prod(counts))} nodes; increase spacing ({spacing} m) "
                          "or grading")
    grid = np.stack(np.meshgrid(lateral, lateral, zs, indexing="ij"), axis=-1).reshape(-1, 3)
    tets = lattice_tets(counts)
    neg = tet_signed_volumes(grid, tets) < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    return Volume(grid, tets, name=f"indent_slab_{'quarter' if quarter else 'full'}")
