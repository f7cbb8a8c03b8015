"""PyBullet's soft body as a peer on the accuracy chart (another engine's soft bodies on the same indentation scene).

``pip install 'surgsim_envs[peers]'`` (PyBullet); without it :func:`available` is False and
``surgsim bench accuracy`` leaves the peers out with a message.

Scene: as :func:`surgsim_envs.bench.mujoco_flex.flex_indent` - the graded slab of
:func:`surgsim_envs.bench.material.indent`, whole (no symmetry conditions), its bottom nodes
anchored to the world (``createSoftBodyAnchor``), a rigid sphere pressed in ``n_depths`` steps,
each a ramp then a hold, zero gravity. PyBullet's deformable world
(``RESET_USE_DEFORMABLE_WORLD``, implicit integration) with the slab loaded from a legacy VTK
tet file in one of two modes:

* ``fem``: ``useNeoHookean`` - Bullet's Neo-Hookean tet FEM with the material's Lamé constants
  ``mu = E / (2 (1 + nu))``, ``lambda = E nu / ((1 + nu)(1 - 2 nu))`` (small strain: linear
  elasticity with E, nu);
* ``mass_spring``: ``useMassSpring`` - a spring on every tet edge, all with one stiffness
  ``k = E h`` (N/m, ``h`` the spacing under the sphere: a cubic spring lattice of spacing ``h``
  has Young's modulus ``k / h``). PyBullet has a single spring constant per body, so springs
  elsewhere (coarser cells) are relatively stiffer; this is PyBullet's model as a user would
  set it up, not a calibrated one.

The sphere is a dynamic body held by a fixed constraint whose pivot is moved (a kinematic
teleport does not push a deformable in Bullet); the force on the sphere is minus the
constraint's reaction (``getConstraintState``), read at the end of each hold. Depth = the
sphere's actual bottom below the undeformed top surface (the constraint is stiff but not
rigid). Penetration = the deepest node inside the sphere (m). Cost = median wall time of one
``stepSimulation`` at ``dt``. Units SI; the scene is built at its true size (m).
"""

from __future__ import annotations

import math
import os
import tempfile
import time

import numpy as np

from surgsim_envs import validate
from surgsim_envs.bench.mujoco_flex import FlexIndentResult
from surgsim_envs.errors import ConfigError, TissueUnstableError

MODES = ("fem", "mass_spring")


def available() -> bool:
    """True when PyBullet can be imported (the ``[peers]`` extra)."""
    try:
        import pybullet  # noqa: F401
    except ImportError:
        return False
    return True


def write_vtk_tets(path: str, nodes: np.ndarray, tets: np.ndarray) -> None:
    """A legacy ASCII VTK unstructured grid of tets (one point / cell per line, as Bullet's
    ``CreateFromVtkFile`` reads it)."""
    nodes = np.asarray(nodes, dtype=float)
    tets = np.asarray(tets, dtype=np.int64)
    if nodes.ndim != 2 or nodes.shape[1] != 3 or tets.ndim != 2 or tets.shape[1] != 4:
        raise ConfigError(f"nodes must be (N,3) and tets (M,4), got {nodes.shape} and {tets.shape}")
    with open(path, "w") as fh:
        fh.write("# vtk DataFile Version 2.0\nsurgsim slab\nASCII\nDATASET UNSTRUCTURED_GRID\n")
        fh.write(f"POINTS {len(nodes)} double\n")
        np.savetxt(fh, nodes, fmt="%.9g")
        fh.write(f"CELLS {len(tets)} {5 * len(tets)}\n")
        np.savetxt(fh, np.column_stack([np.full(len(tets), 4), tets]), fmt="%d")
        fh.write(f"CELL_TYPES {len(tets)}\n")
        np.savetxt(fh, np.full(len(tets), 10), fmt="%d")


def pybullet_indent(mode: str = "fem", material="liver", *, indenter_radius: float = 0.005, depth: float = 0.0015,
                    thickness: float = 0.03, width: float | None = None, spacing: float = 0.006, n_depths: int = 8,
                    dt: float = 1e-3, ramp_steps: int = 20, hold_steps: int = 40, damping: float = 0.01,
                    grading: float = 1.3, margin: float = 1e-4) -> FlexIndentResult:
    """Press a rigid sphere into the slab simulated by PyBullet's soft body in ``mode``
    (module docstring); returns depth (m), force (N, up on the sphere), penetration (m) and cost."""
    if mode not in MODES:
        raise ConfigError(f"PyBullet soft-body mode must be one of {MODES}, got {mode!r}")
    validate.positives(indenter_radius=indenter_radius, depth=depth, thickness=thickness, spacing=spacing, dt=dt,
                       margin=margin, fix="give a positive number (SI units)")
    if depth >= min(indenter_radius, thickness):
        raise ConfigError(f"depth {depth} m must be smaller than the indenter radius and the thickness")
    for key, val in (("n_depths", n_depths), ("ramp_steps", ramp_steps), ("hold_steps", hold_steps)):
        validate.integer(val, key, lo=1, fix="give a positive integer")
    try:
        import pybullet as pb
    except ImportError:
        raise ConfigError("PyBullet is not installed: pip install 'surgsim_envs[peers]' (or pip install pybullet)") from None
    from surgsim_envs.bench.indent_mesh import graded_slab
    from surgsim_envs.materials import get_material

    mat = get_material(material)
    E, nu = float(mat.young), float(mat.poisson)
    width = 4.0 * thickness if width is None else float(width)
    R = float(indenter_radius)
    zone = min(0.999 * R, 1.6 * math.sqrt(R * depth) + 2.0 * spacing) + 2.0 * spacing   # as in material.indent
    vol = graded_slab(width, thickness, spacing, zone, grading=grading, quarter=False)
    fd, path = tempfile.mkstemp(suffix=".vtk", prefix="surgsim_slab_")
    os.close(fd)
    client = pb.connect(pb.DIRECT)
    try:
        write_vtk_tets(path, vol.nodes, vol.tets)
        pb.resetSimulation(pb.RESET_USE_DEFORMABLE_WORLD, physicsClientId=client)
        pb.setGravity(0, 0, 0, physicsClientId=client)
        pb.setTimeStep(dt, physicsClientId=client)
        common = dict(basePosition=[0, 0, 0], scale=1.0, mass=float(mat.density) * width * width * thickness,
                      collisionMargin=margin, useSelfCollision=0, frictionCoeff=0.0, useFaceContact=1,
                      physicsClientId=client)
        if mode == "fem":
            lam = E * nu / ((1 + nu) * (1 - 2 * nu))
            body = pb.loadSoftBody(path, useNeoHookean=1, NeoHookeanMu=E / (2 * (1 + nu)), NeoHookeanLambda=lam,
                                   NeoHookeanDamping=damping, **common)
        else:
            body = pb.loadSoftBody(path, useMassSpring=1, springElasticStiffness=E * spacing,
                                   springDampingStiffness=damping, useBendingSprings=0, **common)
        if body < 0:
            raise ConfigError(f"PyBullet could not load the slab mesh ({len(vol.nodes)} nodes) as a soft body")
        nodes = np.array(pb.getMeshData(body, flags=pb.MESH_DATA_SIMULATION_MESH, physicsClientId=client)[1])
        bottom = np.flatnonzero(np.isclose(nodes[:, 2], -thickness))
        for i in bottom:
            pb.createSoftBodyAnchor(body, int(i), -1, -1, physicsClientId=client)
        top = float(nodes[:, 2].max())
        shape = pb.createCollisionShape(pb.GEOM_SPHERE, radius=R, physicsClientId=client)
        start = [0.0, 0.0, top + R + 0.001]
        ball = pb.createMultiBody(baseMass=0.01, baseCollisionShapeIndex=shape, basePosition=start,
                                  physicsClientId=client)
        hold = pb.createConstraint(ball, -1, -1, -1, pb.JOINT_FIXED, [0, 0, 0], [0, 0, 0], start,
                                   physicsClientId=client)
        max_force = 1e3
        targets = np.linspace(depth / n_depths, depth, n_depths)
        depths, forces, pens = np.empty(n_depths), np.empty(n_depths), np.empty(n_depths)
        times = []
        prev = -0.001
        for k, target in enumerate(targets):
            for i in range(ramp_steps + hold_steps):
                now = prev + (target - prev) * min((i + 1) / ramp_steps, 1.0)
                pb.changeConstraint(hold, jointChildPivot=[0.0, 0.0, top + R - now], maxForce=max_force,
                                    physicsClientId=client)
                t0 = time.perf_counter()
                pb.stepSimulation(physicsClientId=client)
                times.append(time.perf_counter() - t0)
            centre = np.array(pb.getBasePositionAndOrientation(ball, physicsClientId=client)[0])
            x = np.array(pb.getMeshData(body, flags=pb.MESH_DATA_SIMULATION_MESH, physicsClientId=client)[1])
            f = -float(pb.getConstraintState(hold, physicsClientId=client)[2])
            if not (np.all(np.isfinite(x)) and np.all(np.isfinite(centre)) and math.isfinite(f)):
                raise TissueUnstableError(f"pybullet_{mode}", dt, math.nan,
                                          f"non-finite PyBullet state at depth {target * 1e3:.3g} mm")
            depths[k] = top - (centre[2] - R)
            forces[k] = f
            pens[k] = max(0.0, R - float(np.min(np.linalg.norm(x - centre, axis=1))))
            prev = target
        return FlexIndentResult(depths, forces, pens, int(len(nodes)), int(3 * (len(nodes) - len(bottom))),
                                float(np.median(times) * 1e6), float(dt), mode, float(spacing), 1,
                                {"thickness": thickness, "width": width, "radius": R, "young": E, "poisson": nu,
                                 "pinned": int(len(bottom)), "damping": damping, "tets": int(len(vol.tets)),
                                 "spring_k_N_per_m": E * spacing if mode == "mass_spring" else None,
                                 "pybullet_api": int(pb.getAPIVersion(physicsClientId=client))})
    finally:
        pb.disconnect(physicsClientId=client)
        os.unlink(path)


#: slab spacings (m) under the sphere for the chart; PyBullet's implicit deformable solver costs
#: ~30-65 ms per step at 1,125 nodes on the shared 2 cores, so the peers stay coarse
SPACINGS = (0.006, 0.004)
QUICK_SPACINGS = (0.006,)


def peer_sweep(spacings=SPACINGS, models=None, progress: bool = True) -> list[dict]:
    """Rows of the PyBullet peers on the accuracy scene (``"baseline": True``, ``"peer":
    "PyBullet"``), in the format of :func:`surgsim_envs.bench.accuracy.flex_sweep`, for the modes
    named ``pybullet_<mode>`` in ``models`` (None: both); ``[]`` with a message when PyBullet is
    not installed."""
    import sys

    from tqdm import tqdm

    from surgsim_envs.bench.accuracy_scene import MATERIAL, RADIUS, THICKNESS, add_self_error, force_error
    from surgsim_envs.bench.references import dimitriadis_force, dimitriadis_valid_depth
    from surgsim_envs.tissue import get_material

    if not available():
        print("surgsim bench accuracy: PyBullet peers skipped: pybullet is not installed "
              "(pip install 'surgsim_envs[peers]')", file=sys.stderr)
        return []
    mat = get_material(MATERIAL).replace(relax_fraction=0.0, nonlinear=0.0)
    dv = dimitriadis_valid_depth(RADIUS, THICKNESS)
    rows = []
    modes = [m for m in MODES if models is None or f"pybullet_{m}" in models]
    jobs = [(m, s) for m in modes for s in spacings]
    with tqdm(jobs, desc="bench accuracy (PyBullet peers)", unit="case", file=sys.stderr, disable=not progress) as bar:
        for mode, s in bar:
            bar.set_postfix_str(f"{mode} h={s * 1e3:g} mm")
            try:
                res = pybullet_indent(mode, mat, indenter_radius=RADIUS, depth=dv, thickness=THICKNESS, spacing=s)
            except Exception as exc:  # keep sweeping
                print(f"surgsim bench accuracy: pybullet_{mode} h={s}: {exc}", file=sys.stderr)
                continue
            ref = dimitriadis_force(res.depth, RADIUS, mat.young, mat.poisson, THICKNESS, bonded=True)
            rows.append({"scene": "indent", "model": f"pybullet_{mode}", "integrator": "implicit", "spacing": s,
                         "nodes": res.nodes, "dofs": res.dofs, "label": f"{s * 1e3:g}", "dt": res.dt,
                         "us_per_step": res.us_per_step, "us_per_ms": res.us_per_ms,
                         "error": force_error(res.depth, res.force, ref, dv), "depth": res.depth.tolist(),
                         "force": res.force.tolist(), "penetration": res.penetration.tolist(), "baseline": True,
                         "peer": "PyBullet", "info": res.info})
    add_self_error(rows)
    return rows
