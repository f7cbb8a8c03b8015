"""Sphere indentation through a quasi-static model's own step: the scene's penalty contact
(:class:`~surgsim_envs.contact.ContactModel`) fed to ``step(dt, forces, stiffness)`` at each depth
until the state stops changing.

:func:`surgsim_envs.bench.material.indent` obtains the force curve from the model's stiffness
matrix and an exact contact solve, whatever the model's step does; this rig checks the step
itself (for ``fem_static``: the condensed compliance, the implicit penalty, the cached columns).
Same scene: a rigid sphere on the axis of a graded quarter slab bonded to a rigid base, symmetry
planes held per dof (the model option ``fixed_dofs``). Depth = sphere bottom below the undeformed
surface, so the penalty penetration counts as compliance (reported). Units m, N.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError
from surgsim_envs.materials import get_material


@dataclass
class SteppedIndent:
    """``depth`` (m), ``force`` (N, whole slab), ``penetration`` (m, deepest contact node inside
    the sphere), ``steps`` (model steps per depth until converged), ``nodes``."""

    depth: np.ndarray
    force: np.ndarray
    penetration: np.ndarray
    steps: np.ndarray
    nodes: int
    spacing: float


def stepped_indent(model="fem_static", material="liver", *, indenter_radius: float = 0.005, depth: float = 0.0015,
                   thickness: float = 0.03, spacing: float | None = None, n_depths: int = 6,
                   contact_stiffness: float | None = None, max_steps: int = 20000, tol: float = 1e-6,
                   dt: float = 1e-3, contact: str = "scene") -> SteppedIndent:
    """Press a sphere (``indenter_radius`` m) to ``depth`` (m) in ``n_depths`` increments into a
    bonded slab (``thickness`` m, width 4 x thickness) through ``model``'s own step (a registered
    model with ``quasi_static``, ``implicit_contact`` and a ``fixed_dofs`` option).

    contact_stiffness: N/m per node (default 30 x E x spacing: penetration ~ 1 % of the depth).
        The contract's isotropic implicit contact stiffness acts as a stick spring within a step, so
        the surface nodes slide to rest over hundreds of steps (faster for a softer penalty). A depth
        has converged when no node moves more than ``tol`` x depth in a step; ConfigError after
        ``max_steps``.
    contact: ``"scene"`` (the scenes' :class:`ContactModel`: penalty along the sphere's normal) or
        ``"vertical"`` (penalty along z on the gap to the sphere's lower surface: tractions normal
        to the undeformed surface, the linear theory's frictionless contact and the chart's rule).
    """
    from surgsim_envs.bench.indent_mesh import graded_slab
    from surgsim_envs.bench.material import model_class
    from surgsim_envs.contact import SPHERE, ContactModel, ContactParams

    if contact not in ("scene", "vertical"):
        raise ConfigError(f"contact={contact!r}; use 'scene' (ContactModel, sphere normals) or 'vertical'")
    cls = model_class(model)
    for cap in ("quasi_static", "implicit_contact"):
        cls.require(cap, task="stepped indentation (surgsim_envs.bench.stepped_indent)")
    mat = get_material(material)
    validate.positives(indenter_radius=indenter_radius, depth=depth, thickness=thickness, unit="m",
                       fix="give a positive length in m")
    R = float(indenter_radius)
    if depth >= min(R, thickness):
        raise ConfigError(f"depth {depth} m must be below the radius {R} m and the thickness {thickness} m")
    a_max = math.sqrt(R * depth)
    spacing = min(a_max / 2.5, thickness / 6.0) if spacing is None else float(spacing)
    zone = min(0.999 * R, 1.6 * a_max + 2.0 * spacing)
    vol = graded_slab(4.0 * thickness, thickness, spacing, zone + 2.0 * spacing, quarter=True)
    X = vol.nodes
    bottom = np.isclose(X[:, 2], -thickness)
    rollers = np.zeros((len(X), 3), dtype=bool)
    rollers[np.isclose(X[:, 0], 0.0), 0] = True
    rollers[np.isclose(X[:, 1], 0.0), 1] = True
    tissue = cls(vol, mat, fixed=bottom, fixed_dofs=rollers)
    k = 30.0 * mat.young * spacing if contact_stiffness is None else float(contact_stiffness)
    top = np.flatnonzero(np.isclose(X[:, 2], 0.0) & (np.hypot(X[:, 0], X[:, 1]) < zone))
    cm = ContactModel(tissue.n_nodes, top, [0.0], ContactParams(stiffness=k, damping=0.0))
    kind, tool = np.array([SPHERE]), np.array([0])
    size, mat9 = np.array([[R, 0.0, 0.0]]), np.eye(3).reshape(1, 9)
    vel, com = np.zeros((1, 6)), np.zeros((1, 3))
    depths = np.linspace(depth / n_depths, depth, n_depths)
    force, pen, steps = np.zeros(n_depths), np.zeros(n_depths), np.zeros(n_depths, dtype=int)
    for i, d in enumerate(depths):
        centre = np.array([[0.0, 0.0, R - d]])
        r_top = np.hypot(X[top, 0], X[top, 1])
        z_sphere = np.where(r_top < R, (R - d) - np.sqrt(np.maximum(R * R - r_top ** 2, 0.0)), np.inf)
        for s in range(1, max_steps + 1):
            if contact == "scene":
                res = cm.compute(tissue.positions, tissue.velocities, kind, tool, size, centre, mat9, vel, com, dt)
                forces, stiff = res.forces, res.stiffness
            else:
                gap = tissue.positions[top, 2] - z_sphere          # > 0: the node is inside the sphere
                on = gap > 0
                forces = np.zeros_like(tissue.positions)
                stiff = np.zeros(tissue.n_nodes)
                forces[top[on], 2] = -k * gap[on]
                stiff[top[on]] = k
            tissue.step(dt, forces, stiff)
            move = float(np.abs(tissue.velocities).max()) * dt
            if s > 1 and move <= tol * d:
                break
        else:
            raise ConfigError(f"stepped indentation did not converge at depth {d:.3g} m in {max_steps} steps "
                              f"(last node move {move:.3g} m); lower contact_stiffness ({k:.3g} N/m)")
        f = float(tissue.integrated_external_forces[:, 2].sum())
        x = tissue.positions[top]
        inside = R - np.linalg.norm(x - centre[0], axis=1)
        force[i], pen[i], steps[i] = -4.0 * f, max(float(inside.max()), 0.0), s
    return SteppedIndent(depths, force, pen, steps, tissue.n_nodes, spacing)
