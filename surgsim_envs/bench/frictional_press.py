"""A rigid sphere pressed into, then dragged along, a quasi-static FEM slab through the suite's own
penalty contact with Coulomb friction (:class:`surgsim_envs.contact.ContactModel`).

The rig for validating the frictional contact against :mod:`surgsim_envs.bench.contact_references`:
the tissue is ``fem_static`` (small-strain linear tets, equilibrium every step) on a graded slab
bonded to its base, so every force is an equilibrium force of the contact law, with no inertia or
damping in it. The sphere (radius R) moves in increments: down to ``depth`` (m below the rest
surface, a vertical press), then optionally ``slide`` m along +x at that depth. Each increment is a
contact call plus a tissue solve, repeated at the same pose until the nodes stop moving (a
quasi-static hold). The repetition matters: the tissue contract takes one isotropic contact stiffness
per node, so the linearised solve resists the tangential motion of a frictionless or sliding contact
point with k_n too, and each pass moves such a point only about 1 / (1 + k_n / s) of the way to its
equilibrium (s the node's own stiffness); at the fixed point that term vanishes and the contact law
holds exactly.

Symmetry: a straight press uses the quarter slab (x >= 0, y >= 0) and a slide the half slab
(y >= 0), with roller conditions on the symmetry planes. A node on a plane stands for the share of
its full-slab node that lies in the model (1/2 on one plane, 1/4 on the axis), so its contact force
and contact stiffness are scaled by that share before the tissue solve; this is the same contact law
with k_n, k_t scaled per node (the stick/slip decision depends only on their ratio). The reported
forces are those of the whole slab.

Penalty: ``penalty_ratio`` sets k_n = k_t = ratio x E x h per contact node (h the fine spacing): the
penalty's compliance is about 1 / ratio of a surface node's own (each result reports the largest
penetration); a ratio of 10 keeps the passes per increment few.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError
from surgsim_envs.materials import get_material


@dataclass
class FrictionalPressResult:
    """Per increment: sphere centre ``x`` (m, along the slide) and ``depth`` (m below the rest
    surface), the whole-slab ``normal`` force P (N, pressing) and ``tangential`` force Q (N, along +x,
    the force the sphere exerts on the tissue); ``sliding_fraction`` of the contact nodes sliding;
    ``penetration`` (m) the deepest penalty penetration; ``sliding_fraction``: the most contact points
    that slid in one pass of the increment over those in contact at its end. ``info``: mesh and law parameters."""

    x: np.ndarray
    depth: np.ndarray
    normal: np.ndarray
    tangential: np.ndarray
    sliding_fraction: np.ndarray
    penetration: np.ndarray
    info: dict = field(default_factory=dict)


def _half_slab(width: float, thickness: float, spacing: float, fine_extent: float, grading: float,
               max_cell: float):
    """Graded slab with x in [-w/2, w/2], y in [0, w/2], z in [-thickness, 0] (module docstring)."""
    from surgsim_envs.bench.indent_mesh import graded_axis
    from surgsim_envs.geometry.box import lattice_tets
    from surgsim_envs.geometry.volume import Volume, tet_signed_volumes

    half = graded_axis(width / 2, spacing, fine_extent, grading, max_cell)
    xs = np.concatenate([-half[:0:-1], half])
    zs = -graded_axis(thickness, spacing, fine_extent, grading, max_cell)[::-1]
    counts = (len(xs), len(half), len(zs))
    if np.prod(counts) > 200_000:
        raise ConfigError(f"half slab would have {int(np.prod(counts))} nodes; increase spacing ({spacing} m)")
    grid = np.stack(np.meshgrid(xs, half, zs, indexing="ij"), axis=-1).reshape(-1, 3)
    tets = lattice_tets(counts)
    neg = tet_signed_volumes(grid, tets) < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    return Volume(grid, tets, name="frictional_press_half_slab")


def frictional_press(material="liver", *, mu: float = 0.5, radius: float = 0.01, depth: float = 0.001,
                     slide: float = 0.0, thickness: float = 0.03, width: float | None = None,
                     spacing: float | None = None, grading: float = 1.3, max_cell: float | None = None,
                     press_steps: int = 10, slide_steps: int = 20, iterations: int = 200,
                     tolerance: float = 1e-3, penalty_ratio: float = 10.0,
                     tool: str = "sphere") -> FrictionalPressResult:
    """Press a rigid sphere (``radius`` m) ``depth`` m into a bonded slab (``thickness`` m, ``width`` m,
    default 4 x thickness) of ``material`` with tool friction ``mu``, then slide it ``slide`` m along
    +x (module docstring). spacing: fine mesh spacing (m, default a / 6, a the contact radius);
    press_steps, slide_steps: increments; iterations: the most contact + solve passes per increment,
    which stop once no node moves by more than ``tolerance`` x the increment's tool travel.
    tool: "sphere" (``radius`` its radius, a = sqrt(R d)) or "punch", a flat-ended cylinder whose
    face (radius ``radius`` = a) is pressed ``depth`` m into the surface.

    Friction is decided per contact call from the node positions before the solve, so a slide
    increment must stay well below mu times the penalty penetration (else the contact records a
    slip where the tissue would have followed): choose ``slide_steps`` accordingly."""
    from surgsim_envs.bench.indent_mesh import graded_slab
    from surgsim_envs.contact import CYLINDER, SPHERE, ContactModel, ContactParams
    from surgsim_envs.tissue.fem_static import QuasiStaticFEMModel

    mat = get_material(material)
    validate.positives(radius=radius, depth=depth, thickness=thickness, penalty_ratio=penalty_ratio,
                       tolerance=tolerance, fix="give a positive number (SI units)")
    if not (isinstance(mu, (int, float)) and math.isfinite(mu) and mu >= 0):
        raise ConfigError(f"mu must be a Coulomb coefficient >= 0, got {mu!r}")
    if not (isinstance(slide, (int, float)) and math.isfinite(slide) and slide >= 0):
        raise ConfigError(f"slide must be >= 0 m, got {slide!r}")
    if depth >= min(radius, thickness) / 2 or (tool == "punch" and depth >= 0.1 * radius):
        raise ConfigError(f"depth {depth} m must be below half the radius ({radius} m) and the thickness "
                          f"({thickness} m), and a punch's below a tenth of its radius: the slab is small-strain")
    for key, val in (("press_steps", press_steps), ("slide_steps", slide_steps), ("iterations", iterations)):
        validate.integer(val, key, lo=1, fix="give a positive integer")
    if tool not in ("sphere", "punch"):
        raise ConfigError(f"tool must be 'sphere' or 'punch' (a flat-ended cylinder), got {tool!r}")
    a = math.sqrt(radius * depth) if tool == "sphere" else float(radius)
    width = 4.0 * thickness if width is None else float(width)
    h = a / 6.0 if spacing is None else float(spacing)
    zone = 1.6 * a + 2.0 * h + slide
    max_cell = 8.0 * h if max_cell is None else max_cell
    if slide > 0:
        vol = _half_slab(width, thickness, h, zone + 2.0 * h, grading, max_cell)
    else:
        vol = graded_slab(width, thickness, h, zone + 2.0 * h, grading=grading, max_cell=max_cell, quarter=True)
    X = vol.nodes
    bottom = np.isclose(X[:, 2], -thickness)
    on_y = np.isclose(X[:, 1], 0.0)
    on_x = np.isclose(X[:, 0], 0.0) if slide == 0 else np.zeros(len(X), dtype=bool)
    fixed_dofs = np.zeros((len(X), 3), dtype=bool)
    fixed_dofs[on_y, 1] = True
    fixed_dofs[on_x, 0] = True
    share = np.where(on_y, 0.5, 1.0) * np.where(on_x, 0.5, 1.0)      # of the full-slab node in the model
    copies = 2.0 if slide > 0 else 4.0                                  # model copies in the whole slab
    tissue = QuasiStaticFEMModel(vol, mat, fixed=bottom, fixed_dofs=fixed_dofs)
    top = np.isclose(X[:, 2], 0.0)
    reach = 1.6 * a + 2.0 * h                                           # beyond the contact edge
    cand = np.flatnonzero(top & (np.hypot(X[:, 0] - np.clip(X[:, 0], 0.0, slide), X[:, 1]) < reach))
    k = float(penalty_ratio) * mat.young * h
    cm = ContactModel(tissue.n_nodes, cand, [float(mu)], ContactParams(stiffness=k, damping=0.0))
    kind = np.array([SPHERE if tool == "sphere" else CYLINDER])
    size = np.array([[radius, radius if tool == "punch" else 0.0, 0.0]])    # a cylinder's half length = radius
    centre = radius                                                          # above the lowest point
    rot = np.eye(3).reshape(1, 9)
    vel, com = np.zeros((1, 6)), np.zeros((1, 3))
    cm.prepare(kind, np.array([0]), size, 1.0)
    w = share[:, None]
    path = [(0.0, depth * (i + 1) / press_steps) for i in range(press_steps)]
    path += [(slide * (i + 1) / slide_steps, depth) for i in range(slide_steps if slide > 0 else 0)]
    out = {key: np.zeros(len(path)) for key in ("x", "depth", "normal", "tangential", "sliding", "pen", "passes")}
    for s, (x, d) in enumerate(path):
        pos = np.array([[x, 0.0, centre - d]])
        sliding = 0
        travel = depth / press_steps if s < press_steps else slide / slide_steps
        for passes in range(1, iterations + 1):
            res = cm.compute_prepared(tissue.positions, tissue.velocities, pos, rot, vel, com)
            sliding = max(sliding, int(cm.report.slipping[0]))      # a relocated anchor sticks next pass
            tissue.step(1.0, res.forces * w, res.stiffness * share)
            if np.abs(tissue.velocities).max() <= tolerance * travel:   # velocities = change per pass (dt 1)
                break
        g = tissue.integrated_external_forces
        out["x"][s], out["depth"][s] = x, d
        out["passes"][s] = passes
        out["normal"][s] = -copies * g[:, 2].sum()
        out["tangential"][s] = copies * g[:, 0].sum() if slide > 0 else 0.0
        n_on = int(cm.report.contacts[0])
        out["sliding"][s] = min(sliding / n_on, 1.0) if n_on else 0.0
        out["pen"][s] = float(cm.report.penetration[0])
    return FrictionalPressResult(out["x"], out["depth"], out["normal"], out["tangential"], out["sliding"], out["pen"],
                                 {"nodes": int(tissue.n_nodes), "spacing": h, "max_passes": int(out["passes"].max()),
                                  "contact_radius": a, "tool": tool,
                                  "stiffness_per_node": k, "mu": float(mu), "radius": float(radius),
                                  "thickness": float(thickness), "width": width, "young": mat.young,
                                  "poisson": mat.poisson})
