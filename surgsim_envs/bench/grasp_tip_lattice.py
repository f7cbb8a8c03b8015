"""The grasp reference's organ lattice graded towards the tip: fine where the jaws grasp, coarse
along the rest of the organ.

The three jaws close on the organ's +x end (the grasp scene places them around it): at 3.89 mm,
closure 0.2, the loaded nodes span 23-51 mm of the organ's 115 mm length and nearly its whole
cross-section there. A uniform lattice refines all of it; this one is uniform at ``fine`` over the
last ``length`` m of the organ (and everywhere in y and z) and grows by ``ratio`` per cell to
``coarse`` towards the held end (:func:`surgsim_envs.geometry.graded_axis.graded_axis` on x,
:func:`surgsim_envs.geometry.mapped_lattice.mapped_lattice_volume`). At 0.97 mm it has about a third
of the uniform lattice's nodes.

The lattice fills the task's placed organ surface (the smooth surface the task's lattice was
meshed from, where the task put it), so the organ's outline does not move between levels; the
uniform lattices are centred by their nodes' bounding box, which moves that surface by up to
0.07 mm between the levels from 3.89 mm down. Units: m.
"""

from __future__ import annotations

import copy

import numpy as np

from surgsim_envs.errors import ConfigError

#: m, the graded lattice's coarse spacing along the held part of the organ
TIP_COARSE_SPACING = 0.00275
#: growth of the cells' x length per cell from the fine tip part to the coarse part
TIP_RATIO = 1.3


def tip_graded_volume(tissue, fine: float, length: float, coarse: float | None = None,
                      ratio: float = TIP_RATIO):
    """A Volume (world frame, m) filling the placed surface of ``tissue`` (a TissueConfig of the grasp
    scene, rotation none) with lattice tets at ``fine`` over the last ``length`` m of its +x end and
    growing to ``coarse`` (None: :data:`TIP_COARSE_SPACING`) beyond (module docstring). It carries
    ``source_surface`` and ``fine``."""
    from surgsim_envs.geometry.graded_axis import graded_axis
    from surgsim_envs.geometry.mapped_lattice import MARGIN_CELLS, mapped_lattice_volume
    from surgsim_envs.scene.builder import placed_volume

    if any(float(a) != 0.0 for a in tissue.euler):
        raise ConfigError("tip_graded_volume: the organ must be unrotated (euler (0, 0, 0)); its lattice is graded "
                          "along the world x axis")
    coarse = TIP_COARSE_SPACING if coarse is None else coarse
    fine, length, coarse = float(fine), float(length), float(coarse)
    if not (0.0 < fine <= coarse):
        raise ConfigError(f"tip_graded_volume: fine spacing {fine} m must be > 0 and <= the coarse {coarse} m")
    placed = placed_volume(copy.deepcopy(tissue))
    src = getattr(placed, "source_surface", None)
    if src is None:
        raise ConfigError(f"tip_graded_volume: organ {tissue.organ!r} carries no source surface to fill; use a "
                          "procedural organ or a surface mesh file")
    vertices, faces = src
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    if not (0.0 < length < hi[0] - lo[0]):
        raise ConfigError(f"tip_graded_volume: length {length} m must be in (0, {hi[0] - lo[0]:.4g}) m, the organ's "
                          "length")
    pad = (MARGIN_CELLS + 1) * coarse
    tip = hi[0]
    # fine on [tip - length, tip + pad]: the anchor is that span's centre, a node
    x = graded_axis(lo[0] - pad, tip + pad, tip + (pad - length) / 2.0, (length + pad) / 2.0, fine, coarse, ratio,
                    what="tip_graded_volume x")
    y, z = (lo[k] - pad + fine * np.arange(int(np.ceil((hi[k] - lo[k] + 2 * pad) / fine)) + 1) for k in (1, 2))
    vol = mapped_lattice_volume((vertices, faces), (x, y, z), name=placed.name)
    vol.source_surface = (np.asarray(vertices, dtype=np.float64).copy(), np.asarray(faces).copy())
    vol.fine = fine
    return vol


__all__ = ["TIP_COARSE_SPACING", "TIP_RATIO", "tip_graded_volume"]
