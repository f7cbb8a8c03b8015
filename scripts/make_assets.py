"""Regenerate the shipped assets in the top-level ``assets/`` folder (deterministic; no data files).

    python scripts/make_assets.py

* ``assets/meshes/kidney.stl``: a procedural kidney surface in metres (an ellipsoid of
  11 x 6 x 3.5 cm, an adult kidney's size, bent into a bean and dented at the hilum). Closed and
  self-intersection free, so it loads as ``organ=`` (lattice-filled into tets).
* ``assets/textures/colormap.png``: the 256 x 1 colour map the scenes use to paint node fields
  (:func:`surgsim_envs.scene.field_colors.colormap_rgb`).

There are no tool meshes: the probe, grasper and proxy are built from MuJoCo primitives.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1] / "assets"

#: semi-axes (m) of the kidney's ellipsoid: length 11 cm, width 6 cm, thickness 3.5 cm
KIDNEY_SEMI_AXES = (0.055, 0.030, 0.0175)
#: bend (m of y at the poles) and hilum dent depth (m) of the bean shape
KIDNEY_BEND, KIDNEY_HILUM_DEPTH = 0.008, 0.010


def kidney_surface(subdivisions: int = 4):
    """trimesh.Trimesh of the procedural kidney (metres, centred at the origin)."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    u = np.asarray(sphere.vertices, dtype=np.float64)
    a, b, c = KIDNEY_SEMI_AXES
    v = u * np.array([a, b, c])
    # bean: the poles (|x| large) bend toward -y, the medial side (-y) gets a smooth hilum dent
    v[:, 1] -= KIDNEY_BEND * (u[:, 0] ** 2)
    medial = np.clip(-u[:, 1], 0.0, None)
    v[:, 1] += KIDNEY_HILUM_DEPTH * medial ** 2 * np.exp(-(u[:, 0] / 0.45) ** 2 - (u[:, 2] / 0.8) ** 2)
    mesh = trimesh.Trimesh(v, sphere.faces, process=True)
    assert mesh.is_watertight and mesh.is_volume, "the procedural kidney must be a closed volume"
    return mesh


def main() -> None:
    import cv2

    from surgsim_envs.scene.field_colors import colormap_rgb

    (ROOT / "meshes").mkdir(parents=True, exist_ok=True)
    (ROOT / "textures").mkdir(parents=True, exist_ok=True)
    mesh = kidney_surface()
    mesh.export(ROOT / "meshes" / "kidney.stl")
    cv2.imwrite(str(ROOT / "textures" / "colormap.png"), np.ascontiguousarray(colormap_rgb()[..., ::-1]))
    print(f"wrote {ROOT / 'meshes' / 'kidney.stl'} ({len(mesh.faces)} triangles, {mesh.volume * 1e6:.1f} cm^3), "
          f"{ROOT / 'textures' / 'colormap.png'}")


if __name__ == "__main__":
    main()
