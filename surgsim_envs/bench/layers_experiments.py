"""Lin et al. 2008's experiments with the ``layered`` model (Figs. 2.14-2.16), as functions tests and
``scripts/layered_figures.py`` share.

A position-controlled spherical probe (:class:`~surgsim_envs.contact.kinematic_probe.KinematicProbe`)
holds the top-surface nodes it covers; every pose is solved to the all-node equilibrium
(``static_solve``) and the probe force is the spring force of its contact mass points with force
accumulation (eqs. 2.4-2.5). Units: m, N.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.contact.kinematic_probe import KinematicProbe
from surgsim_envs.geometry.anatomy import abdominal_wall_volume, thigh_volume
from surgsim_envs.tissue.layered import LayeredModel

#: abdominal wall of Fig. 2.15: the fat thins towards -x (muscle shallower there)
WALL = {"size": (0.12, 0.08), "fat_variation": 0.4}
#: leg section of Fig. 2.16: 23 mm of soft tissue over the femur
LEG = {"radius": 0.035, "length": 0.06, "fat": 0.008, "bone_radius": 0.012, "bone_offset": 0.0}


def wall_model(spacing: float = 0.004, **kwargs) -> tuple[LayeredModel, np.ndarray]:
    """(model with the bottom bonded, top-surface node indices) of an abdominal wall patch."""
    opts = {**WALL, **kwargs}
    vol = abdominal_wall_volume(spacing, **opts)
    bottom = vol.face_nodes(4)  # no node below: the whole bottom face
    model = LayeredModel(vol, fixed=bottom)
    top = np.flatnonzero(vol.neighbours[:, 5] < 0)
    return model, top


def path_forces(model: LayeredModel, top: np.ndarray, depth: float, xs, radius: float = 0.005) -> dict:
    """Probe pressed ``depth`` m below the top surface and moved along x at y = 0 (Fig. 2.15).
    Returns {x, force (upward, N), active (nodes moved), fat_thickness under the probe (m)}."""
    z_top = float(model.rest_positions[top, 2].max())
    probe = KinematicProbe(model, top, radius)
    forces, active = [], []
    for x in xs:
        probe.move_to((float(x), 0.0, z_top + radius - depth))
        model.static_solve()
        forces.append(float(probe.force()[2]))
        active.append(int(np.count_nonzero(np.linalg.norm(model.positions - model.rest_positions, axis=1) > 1e-6)))
    probe.move_to((1e3, 1e3, 1e3))  # lift off
    model.reset()
    return {"x": [float(x) for x in xs], "force": forces, "active": active, "depth": depth}


def layer_deformation(model: LayeredModel, top: np.ndarray, depth: float = 0.004, radius: float = 0.005) -> dict:
    """Fig. 2.14: press at the centre; mean downward displacement (m) of each material's nodes in the
    column under the probe (|x|, |y| < radius), ordered from the top, and the interpenetration count."""
    z_top = float(model.rest_positions[top, 2].max())
    probe = KinematicProbe(model, top, radius)
    probe.move_to((0.0, 0.0, z_top + radius - depth))
    model.static_solve()
    X, x = model.rest_positions, model.positions
    col = (np.abs(X[:, 0]) < radius) & (np.abs(X[:, 1]) < radius)
    vol = model.volume
    rows = []
    for k, name in enumerate(vol.material_names):
        sel = col & (vol.node_material == k)
        if sel.any():
            rows.append((float(X[sel, 2].mean()), name, float(-(x[sel, 2] - X[sel, 2]).mean())))
    rows.sort(reverse=True)
    out = {"material": [r[1] for r in rows], "height": [r[0] for r in rows], "displacement": [r[2] for r in rows],
           "interpenetrations": model.interpenetrations(), "force": float(probe.force()[2]),
           "positions": x.copy()}
    probe.move_to((1e3, 1e3, 1e3))
    model.reset()
    return out


def leg_model(spacing: float = 0.003, **kwargs) -> tuple[LayeredModel, np.ndarray]:
    """(model with the femur rigid, nodes on the upper half of the skin) of a leg section."""
    vol = thigh_volume(spacing, **{**LEG, **kwargs})
    model = LayeredModel(vol)
    top = np.flatnonzero((vol.neighbours[:, 5] < 0) & (vol.nodes[:, 2] > 0.0))
    return model, top


def bone_press(model: LayeredModel, top: np.ndarray, depths, radius: float = 0.008) -> dict:
    """Fig. 2.16: probe pushed down towards the femur; {depth, force (N), rigid_springs}."""
    z_top = float(model.rest_positions[top, 2].max())
    probe = KinematicProbe(model, top, radius)
    forces, rigid = [], []
    for d in depths:
        probe.move_to((0.0, 0.0, z_top + radius - float(d)))
        model.static_solve()
        forces.append(float(probe.force()[2]))
        rigid.append(int(np.count_nonzero(model.push > 0.0)))
    probe.move_to((1e3, 1e3, 1e3))
    model.reset()
    soft = z_top - float(model.rest_positions[model.rigid_nodes, 2].max())
    return {"depth": [float(d) for d in depths], "force": forces, "rigid_springs": rigid, "soft_thickness": soft}
