"""The three-jaw large-organ grasper of the grasping simulation paper. One tool kind = this module + registration.

The wrist body's local +z axis points from the jaw tips back towards the handle, i.e. ``-axis``.
The wrist slides along its local x, y (across) and z (along the axis). Jaw i sits at angle
``120 i`` degrees about the axis; its slide joint moves it radially inwards (``qpos`` = closing
travel, m). Jaw 1 is actuated; jaws 2 and 3 follow through joint-coupling equalities, so the
three jaws always move in parallel. Commands: :meth:`GrasperTool.set_jaw_opening`,
:meth:`GrasperTool.set_grip`; readouts: :meth:`GrasperTool.jaw_opening`,
:meth:`GrasperTool.jaw_forces`. Units: m, kg, N, rad.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import mujoco
import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.scene.config import GrasperConfig, rate_limit, vec
from surgsim_envs.scene.tools.base import (_SLIDE, TOOL_CONAFFINITY, TOOL_CONTYPE, ToolSpec, _mat2quat,
                                           _rotation_to, _slide_drive)
from surgsim_envs.validate import positive

KIND = "grasper"
DRIVES = ("position", "proxy", "free")
#: how the tissue contact meets the jaws' edges (GrasperConfig.jaw_edges)
JAW_EDGES = ("sharp", "round")


@dataclass
class GrasperTool(ToolSpec):
    """A built three-jaw grasper with its jaw commands and readouts."""

    def actuator_rates(self) -> dict[int, float]:
        rates = super().actuator_rates()
        rates[int(self.jaw_actuator_id)] = float(self.config.closing_speed)
        return rates

    @property
    def has_grip(self) -> bool:
        return True

    def set_jaw_opening(self, sim, radius: float, speed: float | None = None) -> None:
        """Close or open to ``radius`` m (axis to each jaw's inner face) at ``speed`` m/s."""
        cfg = self.config
        if not (isinstance(radius, (int, float)) and cfg.min_radius - 1e-12 <= radius <= cfg.open_radius + 1e-12):
            raise ConfigError(f"jaw opening {radius!r} m is outside [{cfg.min_radius}, {cfg.open_radius:.4f}] m "
                              f"(min_radius .. open_radius) of grasper '{self.name}'")
        sim.set_actuator_goal(self.jaw_actuator_id, cfg.open_radius - float(radius), speed)

    def set_grip(self, sim, value: float, speed: float | None = None) -> None:
        """``value`` in [0, 1]: jaw opening from ``open_radius`` (0) to ``min_radius`` (1)."""
        cfg = self.config
        g = float(np.clip(value, 0.0, 1.0))
        self.set_jaw_opening(sim, cfg.open_radius - g * (cfg.open_radius - cfg.min_radius), speed)

    def jaw_opening(self, sim) -> float:
        """Current distance (m) from the axis to jaw 1's inner face."""
        return float(self.config.open_radius - sim.data.qpos[self.jaw_qpos_adr[0]])

    def jaw_forces(self, sim) -> dict[str, np.ndarray]:
        """Per-jaw contact forces: {"normal": (3,) N, "tangential": (3,) N} (last physics step)."""
        cached = getattr(self, "_jaw_rows", None)
        if cached is None or cached[0]() is not sim:    # rows of this sim's contact arrays, looked up once
            cached = self._jaw_rows = (weakref.ref(sim), np.array(sim.geom_rows(self.jaw_geom_ids), dtype=np.int64))
        rows = cached[1]
        if len(sim.contacts) == 1:                     # 0 + the rows, as the sum below
            r = next(iter(sim.contacts.values())).result
            return {"normal": r.geom_normal_force[rows] + 0.0, "tangential": r.geom_tangential_force[rows] + 0.0}
        fn, ft = np.zeros(3), np.zeros(3)
        for contact in sim.contacts.values():
            fn += contact.result.geom_normal_force[rows]
            ft += contact.result.geom_tangential_force[rows]
        return {"normal": fn, "tangential": ft}


def validate(g: GrasperConfig) -> None:
    """ConfigError naming the first bad field of grasper ``g``."""
    for key in ("open_radius", "min_radius", "jaw_length", "jaw_width", "jaw_thickness", "shaft_radius",
                "shaft_length", "closing_speed", "kp", "jaw_kp", "mass", "jaw_mass", "travel"):
        positive(getattr(g, key), f"grasper '{g.name}' {key}", fix="give a positive number in SI units")
    rate_limit(g.speed, f"grasper '{g.name}' speed")
    if g.min_radius >= g.open_radius:
        raise ConfigError(f"grasper '{g.name}': min_radius={g.min_radius} m must be < open_radius={g.open_radius} m")
    if g.jaw_width / 2 >= g.min_radius * math.sqrt(3):
        raise ConfigError(f"grasper '{g.name}': jaws of width {g.jaw_width} m would collide at min_radius "
                          f"{g.min_radius} m; use min_radius > {g.jaw_width / (2 * math.sqrt(3)):.4f} m")
    ax = vec(g.axis, 3, f"grasper '{g.name}' axis")
    if math.sqrt(sum(a * a for a in ax)) < 1e-9:
        raise ConfigError(f"grasper '{g.name}' axis must be a non-zero direction, got {g.axis!r}")
    vec(g.position, 3, f"grasper '{g.name}' position")
    if g.jaw_edges not in JAW_EDGES:
        raise ConfigError(f"grasper '{g.name}' jaw_edges={g.jaw_edges!r}; choose 'sharp' (box jaws) or 'round' "
                          "(jaw edges rounded to half the jaw thickness in the tissue contact)")
    if g.drive not in DRIVES:
        raise ConfigError(f"grasper '{g.name}' drive={g.drive!r}; choose 'position', 'proxy' or 'free'")


def build(spec: mujoco.MjSpec, cfg: GrasperConfig) -> ToolSpec:
    """Add the three-jaw grasper (the grasping simulation paper) to ``spec``; return its :class:`ToolSpec`."""
    name = cfg.name
    axis = np.asarray(cfg.axis, dtype=float)
    axis /= np.linalg.norm(axis)
    rot = _rotation_to(-axis)  # local +z points back along the shaft
    wrist = spec.worldbody.add_body(name=name, pos=list(map(float, cfg.position)), quat=_mat2quat(rot), gravcomp=1.0)
    wrist.explicitinertial = True
    wrist.mass = cfg.mass
    L = cfg.shaft_length
    ixx = cfg.mass * L * L / 3.0
    wrist.ipos = [0.0, 0.0, L / 2.0]
    wrist.inertia = [ixx, ixx, 0.5 * cfg.mass * cfg.shaft_radius ** 2]
    # slide axes are in the wrist's own frame: across (x, y) and along (z) the tool axis
    joints, acts = _slide_drive(spec, wrist, name, np.eye(3), cfg, cfg.mass, cfg.travel)
    shaft = f"{name}/shaft"
    wrist.add_geom(name=shaft, type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[cfg.shaft_radius, L / 2.0, 0],
                   pos=[0.0, 0.0, L / 2.0], rgba=list(cfg.rgba), contype=TOOL_CONTYPE, conaffinity=TOOL_CONAFFINITY,
                   mass=0.0, density=0.0)
    travel = cfg.open_radius - cfg.min_radius
    jaw_bodies, jaw_geoms, jaw_joints = [], [], []
    t = cfg.jaw_thickness
    for i in range(3):
        theta = float(cfg.roll) + 2.0 * math.pi * i / 3.0
        u = np.array([math.cos(theta), math.sin(theta), 0.0])
        bname = f"{name}/jaw{i + 1}"
        jaw = wrist.add_body(name=bname, pos=(u * (cfg.open_radius + t / 2.0) + [0, 0, -cfg.jaw_length / 2.0]).tolist(),
                             quat=[math.cos(theta / 2), 0.0, 0.0, math.sin(theta / 2)], gravcomp=1.0)
        jaw.explicitinertial = True
        jaw.mass = cfg.jaw_mass
        jaw.ipos = [0.0, 0.0, 0.0]
        Ij = cfg.jaw_mass * (cfg.jaw_length ** 2 + cfg.jaw_width ** 2) / 12.0
        jaw.inertia = [Ij, Ij, cfg.jaw_mass * (cfg.jaw_width ** 2 + t * t) / 12.0]
        jname = f"{name}/jaw{i + 1}_slide"
        # closing travel is positive: the jaw moves along -x of its own frame (towards the axis)
        jaw.add_joint(name=jname, type=_SLIDE, axis=[-1.0, 0.0, 0.0], range=[0.0, travel],
                      limited=mujoco.mjtLimited.mjLIMITED_TRUE)
        gname = f"{name}/jaw{i + 1}_box"
        jaw.add_geom(name=gname, type=mujoco.mjtGeom.mjGEOM_BOX, size=[t / 2.0, cfg.jaw_width / 2.0, cfg.jaw_length / 2.0],
                     rgba=list(cfg.rgba), contype=TOOL_CONTYPE, conaffinity=TOOL_CONAFFINITY, mass=0.0, density=0.0)
        jaw_bodies.append(bname)
        jaw_geoms.append(gname)
        jaw_joints.append(jname)
    for i in (1, 2):
        spec.add_equality(name=f"{name}/couple{i + 1}", type=mujoco.mjtEq.mjEQ_JOINT, name1=jaw_joints[i],
                          name2=jaw_joints[0], objtype=mujoco.mjtObj.mjOBJ_JOINT,
                          data=[0.0, 1.0, 0.0, 0.0, 0.0] + [0.0] * 7, solref=[0.002, 1.0])
    jact = f"{name}/close"
    act = spec.add_actuator(name=jact, target=jaw_joints[0], trntype=mujoco.mjtTrn.mjTRN_JOINT)
    act.set_to_position(kp=cfg.jaw_kp, dampratio=cfg.dampratio)
    act.ctrlrange = [0.0, travel]
    act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
    return GrasperTool(name=name, kind=KIND, config=cfg, body=name, contact_geoms=[shaft, *jaw_geoms],
                       rounded_geoms=list(jaw_geoms) if cfg.jaw_edges == "round" else [],
                    joints=joints, actuators=acts, jaw_bodies=jaw_bodies, jaw_geoms=jaw_geoms, jaw_joints=jaw_joints,
                    jaw_actuator=jact, home=np.asarray(cfg.position, dtype=float), frame=rot)


