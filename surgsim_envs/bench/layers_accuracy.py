"""Layered model against FEM on the same layered volume: a rigid sphere pressed into an abdominal wall.

Both models are linearised about rest (``stiffness_matrix``: the layered springs of eq. 2.8, the
project's tet FEM with averaged nodal pressure on the same lattice tets and the same per-layer
materials). The contact nodes (top-surface nodes under the sphere) are held on the sphere
(:func:`surgsim_envs.contact.kinematic_probe.sphere_contact`), the bottom is bonded, and the force
is the sum of the reactions at the contact nodes. Depths stay small enough that the layered
model's NBB constraints do not engage (checked). Units: m, N.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla

from surgsim_envs.contact.kinematic_probe import sphere_contact

#: patch and tool of the comparison (m): an 8 x 8 cm abdominal wall patch, a flat punch of radius 10 mm
#: (nodal contact needs a contact radius of several lattice spacings)
PATCH = (0.08, 0.08)
RADIUS = 0.010
DEPTHS = (0.0005, 0.001, 0.0015, 0.002)
SPACINGS = (0.004, 0.003, 0.002, 0.0015)


def punch_contact(rest: np.ndarray, candidates: np.ndarray, centre_xy, radius: float, depth: float):
    """Contact nodes and targets of a rigid flat cylindrical punch (``radius`` m) pressed ``depth`` m."""
    x = rest[candidates]
    hit = np.hypot(x[:, 0] - centre_xy[0], x[:, 1] - centre_xy[1]) < radius
    targets = x[hit].copy()
    targets[:, 2] -= depth
    return candidates[hit], targets


def press_linear(K, rest: np.ndarray, fixed: np.ndarray, candidates: np.ndarray, centre_xy, radius: float,
                 depths, top_z: float, punch: bool = True) -> np.ndarray:
    """Force (N, upward on the tool) per depth for a linear model with stiffness ``K`` (3N x 3N):
    a flat punch (``punch``) or a sphere of ``radius`` m."""
    n = len(rest)
    K = K.tocsr()
    out = []
    for depth in depths:
        if punch:
            nodes, targets = punch_contact(rest, candidates, centre_xy, radius, depth)
        else:
            nodes, targets = sphere_contact(rest, candidates, (centre_xy[0], centre_xy[1], top_z + radius - depth),
                                            radius)
        u = np.zeros((n, 3))
        u[nodes] = targets - rest[nodes]
        held = fixed.copy()
        held[nodes] = True
        dof_held = np.repeat(held, 3)
        free = np.flatnonzero(~dof_held)
        hd = np.flatnonzero(dof_held)
        uh = u.reshape(-1)[hd]
        rhs = -(K[free][:, hd] @ uh)
        uf = spla.splu(K[free][:, free].tocsc()).solve(rhs)
        full = np.zeros(3 * n)
        full[hd] = uh
        full[free] = uf
        reaction = (K @ full).reshape(n, 3)
        out.append(-reaction[nodes, 2].sum())
    return np.asarray(out)


def compare(spacing: float, patch=PATCH, radius: float = RADIUS, depths=DEPTHS, **layers) -> dict:
    """{spacing, nodes, depth, layered, fem, error} for one lattice spacing (m)."""
    from surgsim_envs.geometry.anatomy import abdominal_wall_volume
    from surgsim_envs.tissue.fem import TetFEMModel
    from surgsim_envs.tissue.layered import LayeredModel

    vol = abdominal_wall_volume(spacing, size=patch, **layers)
    bottom = vol.face_nodes(4)  # no node below: the whole bottom face
    top = np.flatnonzero(vol.neighbours[:, 5] < 0)
    top_z = float(vol.nodes[top, 2].max())
    lay = LayeredModel(vol, fixed=bottom)
    regions = {k: vol.material_table[m] for k, m in enumerate(vol.layer_names)}
    fem = TetFEMModel(vol, regions[0], region_materials=regions, fixed=bottom, corotational=False)
    f_lay = press_linear(lay.stiffness_matrix(), vol.nodes, bottom, top, (0.0, 0.0), radius, depths, top_z)
    f_fem = press_linear(fem.stiffness_matrix(), vol.nodes, bottom, top, (0.0, 0.0), radius, depths, top_z)
    return {"spacing": spacing, "nodes": int(vol.n_nodes), "depth": list(depths), "layered": f_lay.tolist(),
            "fem": f_fem.tolist(), "error": float(np.mean(np.abs(f_lay / f_fem - 1.0)))}
