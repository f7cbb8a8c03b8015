"""MuJoCo's own 3-D flex (built-in elasticity) as a baseline tissue, shared by the benchmarks.

* :func:`flexcomp_xml` -- the ``<flexcomp dim="3">`` element: a uniform ``grid`` or a ``direct``
  tet mesh, ``dof="full"`` (three slide dofs per vertex) or ``dof="trilinear"`` (dofs on a
  ``cellcount`` background grid, the vertices interpolated), elasticity from Young's modulus and
  Poisson's ratio, bottom pinned. Used by ``surgsim bench loop`` (probe press of a cube) and
  :func:`flex_indent`.
* :func:`flex_indent` -- the indentation scene of ``surgsim bench accuracy`` (rigid sphere into a
  slab bonded to a rigid base, the same graded mesh as our models but full instead of a quarter)
  simulated by MuJoCo: force on the sphere against its depth, contact penetration, cost.

MuJoCo 4.0 facts this relies on: flex elasticity is integrated only by ``integrator="discrete"``
(implicitly; not under implicit/implicitfast, and Euler diverges at 1 ms); for ``trilinear`` dofs
``<pin gridrange>`` takes interpolation-node coordinates (0..cellcount per axis), not vertex
coordinates. Units: SI (m, kg, s, N, Pa).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError, TissueUnstableError

DOFS = ("full", "trilinear")


def _fmt(values) -> str:
    return " ".join(f"{float(v):.9g}" for v in np.ravel(values))


def flexcomp_xml(name: str, *, young: float, poisson: float, mass: float, dof: str = "full", damping: float = 0.005,
                 radius: float = 0.0005, solref: float = 0.002, condim: int = 3, count=None, spacing=None, pos=None,
                 points=None, tets=None, pin_ids=None, cellcount: int = 1) -> str:
    """``<flexcomp dim="3">`` XML (a string to put in ``<worldbody>``).

    Grid form: ``count`` (3 ints, vertices per axis), ``spacing`` (m), ``pos`` (m, grid centre); the
    bottom layer (z index 0) is pinned. Direct form: ``points`` (N,3) m, ``tets`` (M,4) vertex ids,
    ``pin_ids`` the vertices to pin (full dofs). For ``dof="trilinear"`` the bottom interpolation
    nodes of the ``cellcount``^3 background grid are pinned instead (pinning vertices is not allowed).
    young (Pa), poisson, mass (kg, whole flex), damping (s, Rayleigh), radius (m, collision skin),
    solref (s, contact time constant; >= 2 dt).
    """
    if dof not in DOFS:
        raise ConfigError(f"dof must be one of {DOFS}, got {dof!r}")
    validate.positives(young=young, mass=mass, radius=radius, solref=solref, fix="give a positive number (SI units)")
    if not (0.0 <= poisson < 0.5):
        raise ConfigError(f"poisson must be in [0, 0.5), got {poisson!r}")
    validate.integer(cellcount, "cellcount", lo=1, fix="give a positive integer")
    dof_attr = "" if dof == "full" else f'dof="{dof}"'
    if count is not None:
        if points is not None:
            raise ConfigError("give either count/spacing/pos (grid) or points/tets (direct), not both")
        count = tuple(int(c) for c in count)
        last = count[0] - 1 if dof == "full" else 1
        return f"""<flexcomp name="{name}" type="grid" dim="3" count="{count[0]} {count[1]} {count[2]}" spacing="{spacing[0]} {spacing[1]} {spacing[2]}"
  pos="{pos[0]:g} {pos[1]:g} {pos[2]}" mass="{mass}" radius="{radius}" {dof_attr}>
  <edge equality="false"/><elasticity young="{young}" poisson="{poisson}" damping="{damping}"/>
  <contact condim="{condim}" solref="{solref} 1" selfcollide="none"/>
  <pin gridrange="0 0 0 {last} {last} 0"/>
</flexcomp>"""
    if points is None or tets is None:
        raise ConfigError("flexcomp_xml needs count/spacing/pos (grid) or points/tets (direct)")
    points = np.asarray(points, dtype=float)
    tets = np.asarray(tets, dtype=np.int64)
    if points.ndim != 2 or points.shape[1] != 3 or tets.ndim != 2 or tets.shape[1] != 4:
        raise ConfigError(f"points must be (N,3) and tets (M,4), got {points.shape} and {tets.shape}")
    if dof == "full":
        if pin_ids is None or len(pin_ids) == 0:
            raise ConfigError("a full-dof direct flex needs pin_ids (the clamped vertices)")
        pin = f'<pin id="{" ".join(str(int(i)) for i in pin_ids)}"/>'
        cells = ""
    else:
        pin = f'<pin gridrange="0 0 0 {cellcount} {cellcount} 0"/>'
        cells = f'cellcount="{cellcount} {cellcount} {cellcount}"'
    return f"""<flexcomp name="{name}" type="direct" dim="3" point="{_fmt(points)}"
  element="{" ".join(str(int(i)) for i in tets.ravel())}" mass="{mass:g}" radius="{radius}" {dof_attr} {cells}>
  <edge equality="false"/><elasticity young="{young}" poisson="{poisson}" damping="{damping}"/>
  <contact condim="{condim}" solref="{solref} 1" selfcollide="none"/>
  {pin}
</flexcomp>"""


def contact_force_on(m, d, geom_id: int) -> tuple[np.ndarray, float, int]:
    """Total contact force (N, world frame) ON geom ``geom_id``, its deepest penetration (m, >= 0)
    and the number of its contacts, from ``mj_contactForce`` over the active contacts."""
    import mujoco

    total = np.zeros(3)
    pen, n = 0.0, 0
    f6 = np.zeros(6)
    for i in range(d.ncon):
        c = d.contact[i]
        if c.geom[0] != geom_id and c.geom[1] != geom_id:
            continue
        mujoco.mj_contactForce(m, d, i, f6)
        world = c.frame.reshape(3, 3).T @ f6[:3]   # frame rows: normal (geom1 -> geom2), tangents
        total += world if c.geom[1] == geom_id else -world
        pen = max(pen, -float(c.dist))
        n += 1
    return total, pen, n


# ----------------------------------------------------------------------------------------------
# Indentation
@dataclass
class FlexIndentResult:
    """MuJoCo flex indentation: ``depth`` (m, sphere bottom below the undeformed surface), ``force``
    (N, upward contact force on the sphere), ``penetration`` (m, deepest sphere-flex contact
    overlap at each depth), ``nodes`` (flex vertices), ``dofs`` (free dofs), ``us_per_step`` (median
    wall time of one ``mj_step``) at ``dt`` (s)."""

    depth: np.ndarray
    force: np.ndarray
    penetration: np.ndarray
    nodes: int
    dofs: int
    us_per_step: float
    dt: float
    dof: str
    spacing: float
    cellcount: int
    info: dict = field(default_factory=dict)

    @property
    def us_per_ms(self) -> float:
        """Compute cost per simulated millisecond (us / ms)."""
        return self.us_per_step * 1e-3 / self.dt


def indent_scene_xml(dof: str, *, young: float, poisson: float, density: float, radius: float, thickness: float,
                     width: float, spacing: float, zone: float, cellcount: int = 1, dt: float = 1e-3,
                     damping: float = 0.002, grading: float = 1.3, skin: float = 1e-4) -> tuple[str, int]:
    """MJCF of the indentation scene and the number of pinned vertices: a full graded slab (top at
    z = 0, bottom z = -thickness pinned) as a ``direct`` flex and a mocap sphere of ``radius``."""
    from surgsim_envs.bench.indent_mesh import graded_slab

    vol = graded_slab(width, thickness, spacing, zone, grading=grading, quarter=False)
    bottom = np.flatnonzero(np.isclose(vol.nodes[:, 2], -thickness))
    flex = flexcomp_xml("slab", young=young, poisson=poisson, mass=density * width * width * thickness, dof=dof,
                        damping=damping, radius=skin, solref=2.0 * dt, condim=1, points=vol.nodes, tets=vol.tets,
                        pin_ids=bottom, cellcount=cellcount)
    xml = f"""<mujoco><option timestep="{dt}" integrator="discrete" gravity="0 0 0"/>
<worldbody>
{flex}
<body name="ball" mocap="true" pos="0 0 {radius + 0.001}"><geom name="ball" type="sphere" size="{radius}"/></body>
</worldbody></mujoco>"""
    return xml, len(bottom)


def flex_indent(dof: str = "full", material="liver", *, indenter_radius: float = 0.005, depth: float = 0.0015,
                thickness: float = 0.03, width: float | None = None, spacing: float = 0.006, cellcount: int = 1,
                n_depths: int = 8, dt: float = 1e-3, ramp_time: float = 0.05, hold_time: float = 0.1,
                damping: float = 0.002, grading: float = 1.3) -> FlexIndentResult:
    """Press a rigid sphere (``indenter_radius`` m, a mocap body) into a slab (``width`` m, default
    4 x ``thickness``) bonded to a rigid base, simulated by MuJoCo's 3-D flex with its built-in
    elasticity (``dof`` "full" or "trilinear" with a ``cellcount``^3 interpolation grid).

    The slab is the graded mesh of :func:`surgsim_envs.bench.material.indent` (``spacing`` m under
    the sphere), whole (MuJoCo has no symmetry conditions). The sphere goes down in ``n_depths``
    steps to ``depth`` (m): each a ``ramp_time`` (s) ramp, then ``hold_time`` (s) at rest so the
    flex settles (Rayleigh ``damping``, s); the force on the sphere (sum of its contact forces) is
    read at the end of each hold. Raises TissueUnstableError if MuJoCo's state goes non-finite.
    """
    import mujoco

    from surgsim_envs.materials import get_material

    mat = get_material(material)
    validate.positives(indenter_radius=indenter_radius, depth=depth, thickness=thickness, spacing=spacing, dt=dt,
                       ramp_time=ramp_time, hold_time=hold_time, fix="give a positive number (SI units)")
    if depth >= min(indenter_radius, thickness):
        raise ConfigError(f"depth {depth} m must be smaller than the indenter radius and the thickness")
    validate.integer(n_depths, "n_depths", lo=1, fix="give a positive integer")
    width = 4.0 * thickness if width is None else float(width)
    R = float(indenter_radius)
    a_max = math.sqrt(R * depth)
    zone = min(0.999 * R, 1.6 * a_max + 2.0 * spacing) + 2.0 * spacing   # as in material.indent
    xml, n_pinned = indent_scene_xml(dof, young=mat.young, poisson=mat.poisson, density=mat.density, radius=R,
                                     thickness=thickness, width=width, spacing=spacing, zone=zone,
                                     cellcount=cellcount, dt=dt, damping=damping, grading=grading)
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    top = float(d.flexvert_xpos[:, 2].max())
    gid = m.geom("ball").id
    depths = np.linspace(depth / n_depths, depth, n_depths)
    forces, pens = np.empty(n_depths), np.empty(n_depths)
    n_ramp, n_hold = max(1, int(round(ramp_time / dt))), max(1, int(round(hold_time / dt)))
    times = []
    prev = -0.001
    for k, target in enumerate(depths):
        for i in range(n_ramp + n_hold):
            now = prev + (target - prev) * min((i + 1) / n_ramp, 1.0)
            d.mocap_pos[0] = (0.0, 0.0, top + R - now)
            t0 = time.perf_counter()
            mujoco.mj_step(m, d)
            times.append(time.perf_counter() - t0)
        if not np.all(np.isfinite(d.qpos)):
            raise TissueUnstableError(f"mujoco_flex_{dof}", dt, math.nan,
                                      f"non-finite MuJoCo state at depth {target * 1e3:.3g} mm")
        f, pen, _ = contact_force_on(m, d, gid)
        forces[k], pens[k] = f[2], pen
        prev = target
    return FlexIndentResult(depths, forces, pens, int(m.nflexvert), int(m.nv), float(np.median(times) * 1e6),
                            float(dt), dof, float(spacing), int(cellcount),
                            {"thickness": thickness, "width": width, "radius": R, "young": mat.young,
                             "poisson": mat.poisson, "pinned": n_pinned, "damping": damping})
