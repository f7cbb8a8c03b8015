"""Layered wall force against FEM for the ``layered`` model's stiffness forms.

The comparison of :mod:`surgsim_envs.bench.layers_accuracy` (abdominal wall patch, bottom face
bonded, rigid flat punch pressed ``depth``, linear models on the same lattice, per-layer
materials) for ``stiffness="paper"`` (eq. 2.8 springs), ``stiffness="elastic"`` (per-tet shear +
per-cell mean-dilatation volume term) and the project's FEM (ANP tets), at several spacings so the
FEM's convergence is shown. Nothing is fitted.

Usage: ``PYTHONPATH=. python scripts/layered_elastic_accuracy.py PATCH_M RADIUS_M SPACING [SPACING ...]
[--no-fem] [--no-paper]``; prints one JSON line per spacing (forces in N at 1 mm).
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np

from surgsim_envs.bench.layers_accuracy import press_linear
from surgsim_envs.geometry.anatomy import abdominal_wall_volume
from surgsim_envs.tissue.layered import LayeredModel

DEPTH = 0.001


def forces(patch: float, radius: float, spacing: float, fem: bool = True, paper: bool = True) -> dict:
    vol = abdominal_wall_volume(spacing, size=(patch, patch))
    bottom = vol.face_nodes(4)
    top = np.flatnonzero(vol.neighbours[:, 5] < 0)
    top_z = float(vol.nodes[top, 2].max())
    out = {"patch": patch, "radius": radius, "spacing": spacing, "nodes": int(vol.n_nodes), "depth": DEPTH}
    forms = (("paper",) if paper else ()) + ("elastic",)
    for form in forms:
        t = time.time()
        k = LayeredModel(vol, fixed=bottom, stiffness=form).stiffness_matrix()
        out[form] = float(press_linear(k, vol.nodes, bottom, top, (0.0, 0.0), radius, (DEPTH,), top_z)[0])
        out[form + "_s"] = round(time.time() - t, 1)
    if fem:
        from surgsim_envs.tissue.fem import TetFEMModel

        t = time.time()
        regions = {k: vol.material_table[m] for k, m in enumerate(vol.layer_names)}
        fm = TetFEMModel(vol, regions[0], region_materials=regions, fixed=bottom, corotational=False)
        out["fem"] = float(press_linear(fm.stiffness_matrix(), vol.nodes, bottom, top, (0.0, 0.0), radius,
                                        (DEPTH,), top_z)[0])
        out["fem_s"] = round(time.time() - t, 1)
    return out


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    patch, radius = float(args[0]), float(args[1])
    for s in args[2:]:
        print(json.dumps(forces(patch, radius, float(s), "--no-fem" not in sys.argv, "--no-paper" not in sys.argv)),
              flush=True)
