"""Rigid tools built in code with :class:`mujoco.MjSpec`: probe, three-jaw grasper, haptic proxy.

Each ``add_*`` function adds the tool to a spec and returns a :class:`ToolSpec` that records the
MuJoCo names of its bodies, contact geoms, joints and actuators; :meth:`ToolSpec.bind` resolves
them to ids after compilation. Units: m, kg, N, rad.

Conventions
-----------
* Probe: the body origin is the centre of the spherical tip; the rod (capsule) runs up the
  body's +z axis. Slide joints x, y, z (world axes) with position actuators; optional hinges
  about x and y for tilt. ``qpos`` of a slide joint is the displacement from home.
* Grasper: the wrist body's local +z axis points from the jaw tips back towards the handle,
  i.e. ``-axis``. The wrist slides along its local x, y (across) and z (along the axis). Jaw i
  sits at angle ``120 i`` degrees about the axis; its slide joint moves it radially inwards
  (``qpos`` = closing travel, m). Jaw 1 is actuated; jaws 2 and 3 follow through joint-coupling
  equalities, so the three jaws always move in parallel.
* Haptic proxy: a mocap body at the tool's home pose, welded to the tool body (virtual
  coupling). The weld's constraint force is the force the hand feels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from surgsim_envs.scene.config import GrasperConfig, HapticProxyConfig, ProbeConfig

#: contact bits: tools collide with the floor but not with each other
TOOL_CONTYPE, TOOL_CONAFFINITY = 2, 1

_SLIDE, _HINGE = mujoco.mjtJoint.mjJNT_SLIDE, mujoco.mjtJoint.mjJNT_HINGE


@dataclass
class ToolSpec:
    """Names (and after :meth:`bind`, ids) of one tool's MuJoCo elements.

    kind: "probe" or "grasper". body: the main body (probe body / grasper wrist).
    contact_geoms: geoms that touch tissue, each with the body that receives its reaction.
    joints/actuators: the translation (and tilt) drive, in order. jaw_*: grasper jaws.
    home: (3,) m, home position of the tool origin; frame: (3,3) rotation of the drive frame
    (columns are the slide axes in world coordinates).
    """

    name: str
    kind: str
    config: object
    body: str
    contact_geoms: list[str] = field(default_factory=list)
    joints: list[str] = field(default_factory=list)
    actuators: list[str] = field(default_factory=list)
    jaw_bodies: list[str] = field(default_factory=list)
    jaw_geoms: list[str] = field(default_factory=list)
    jaw_joints: list[str] = field(default_factory=list)
    jaw_actuator: str | None = None
    home: np.ndarray = field(default_factory=lambda: np.zeros(3))
    frame: np.ndarray = field(default_factory=lambda: np.eye(3))
    proxy: str | None = None            # mocap body name
    proxy_eq: str | None = None         # weld equality name
    # ids, filled by bind()
    body_id: int = -1
    geom_ids: np.ndarray | None = None
    dof_adr: np.ndarray | None = None
    qpos_adr: np.ndarray | None = None
    actuator_ids: np.ndarray | None = None
    jaw_body_ids: np.ndarray | None = None
    jaw_geom_ids: np.ndarray | None = None
    jaw_qpos_adr: np.ndarray | None = None
    jaw_actuator_id: int = -1
    mocap_id: int = -1
    proxy_eq_id: int = -1

    def bind(self, m: mujoco.MjModel) -> None:
        """Resolve names to ids in the compiled model ``m``."""
        def oid(kind, name):
            return mujoco.mj_name2id(m, kind, name)

        self.body_id = oid(mujoco.mjtObj.mjOBJ_BODY, self.body)
        self.geom_ids = np.array([oid(mujoco.mjtObj.mjOBJ_GEOM, g) for g in self.contact_geoms], dtype=np.int64)
        jids = [oid(mujoco.mjtObj.mjOBJ_JOINT, j) for j in self.joints]
        self.dof_adr = np.array([m.jnt_dofadr[j] for j in jids], dtype=np.int64)
        self.qpos_adr = np.array([m.jnt_qposadr[j] for j in jids], dtype=np.int64)
        self.actuator_ids = np.array([oid(mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in self.actuators], dtype=np.int64)
        self.jaw_body_ids = np.array([oid(mujoco.mjtObj.mjOBJ_BODY, b) for b in self.jaw_bodies], dtype=np.int64)
        self.jaw_geom_ids = np.array([oid(mujoco.mjtObj.mjOBJ_GEOM, g) for g in self.jaw_geoms], dtype=np.int64)
        self.jaw_qpos_adr = np.array([m.jnt_qposadr[oid(mujoco.mjtObj.mjOBJ_JOINT, j)] for j in self.jaw_joints],
                                     dtype=np.int64)
        if self.jaw_actuator:
            self.jaw_actuator_id = oid(mujoco.mjtObj.mjOBJ_ACTUATOR, self.jaw_actuator)
        if self.proxy:
            self.mocap_id = int(m.body_mocapid[oid(mujoco.mjtObj.mjOBJ_BODY, self.proxy)])
            self.proxy_eq_id = oid(mujoco.mjtObj.mjOBJ_EQUALITY, self.proxy_eq)


def _rotation_to(axis) -> np.ndarray:
    """Rotation matrix whose third column is the unit vector ``axis`` (first column horizontal if possible)."""
    z = np.asarray(axis, dtype=float)
    z = z / np.linalg.norm(z)
    helper = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)


def _mat2quat(mat: np.ndarray) -> list[float]:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(mat, dtype=float).reshape(9))
    return q.tolist()


def _slide_drive(spec: mujoco.MjSpec, body, name: str, axes, cfg, mass: float, travel: float) -> tuple[list, list]:
    """Slide joints along ``axes`` (in the body's parent frame... i.e. the body frame at qpos 0)
    with position actuators (unless the tool is proxy-driven)."""
    joints, acts = [], []
    for label, ax in zip("xyz", axes):
        jname = f"{name}/slide_{label}"
        body.add_joint(name=jname, type=_SLIDE, axis=list(ax), range=[-travel, travel], limited=mujoco.mjtLimited.mjLIMITED_TRUE,
                       damping=0.0, armature=0.0)
        joints.append(jname)
        if cfg.drive == "position":
            aname = f"{name}/move_{label}"
            act = spec.add_actuator(name=aname, target=jname, trntype=mujoco.mjtTrn.mjTRN_JOINT)
            act.set_to_position(kp=cfg.kp, dampratio=cfg.dampratio)
            act.ctrlrange = [-travel, travel]
            act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
            acts.append(aname)
    return joints, acts


def add_probe(spec: mujoco.MjSpec, cfg: ProbeConfig) -> ToolSpec:
    """Add a probe (rigid rod with spherical tip) to ``spec``; return its :class:`ToolSpec`."""
    name = cfg.name
    body = spec.worldbody.add_body(name=name, pos=list(map(float, cfg.position)), gravcomp=1.0)
    # inertia: a thin rod of length L about its end plus the tip, roughly
    L = cfg.rod_length
    ixx = cfg.mass * (L * L / 3.0 + cfg.rod_radius ** 2 / 4.0)
    izz = 0.5 * cfg.mass * max(cfg.rod_radius, cfg.tip_radius) ** 2
    body.explicitinertial = True
    body.mass = cfg.mass
    body.ipos = [0.0, 0.0, 0.0]
    body.inertia = [ixx, ixx, izz]
    joints, acts = _slide_drive(spec, body, name, np.eye(3), cfg, cfg.mass, cfg.travel)
    if cfg.orientation:
        for label, ax in (("x", [1, 0, 0]), ("y", [0, 1, 0])):
            jname = f"{name}/tilt_{label}"
            body.add_joint(name=jname, type=_HINGE, axis=ax, range=[-1.0, 1.0], limited=mujoco.mjtLimited.mjLIMITED_TRUE)
            joints.append(jname)
            if cfg.drive == "position":
                aname = f"{name}/tilt_{label}"
                act = spec.add_actuator(name=aname, target=jname, trntype=mujoco.mjtTrn.mjTRN_JOINT)
                act.set_to_position(kp=cfg.kp * L * L, dampratio=cfg.dampratio)
                act.ctrlrange = [-1.0, 1.0]
                act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
                acts.append(aname)
    tip = f"{name}/tip"
    rod = f"{name}/rod"
    body.add_geom(name=tip, type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[cfg.tip_radius, 0, 0], rgba=list(cfg.rgba),
                  contype=TOOL_CONTYPE, conaffinity=TOOL_CONAFFINITY, mass=0.0, density=0.0)
    half = L / 2.0
    body.add_geom(name=rod, type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[cfg.rod_radius, half, 0],
                  pos=[0.0, 0.0, cfg.tip_radius + half], rgba=list(cfg.rgba),
                  contype=TOOL_CONTYPE, conaffinity=TOOL_CONAFFINITY, mass=0.0, density=0.0)
    body.add_site(name=f"{name}/tip_site", size=[0.001, 0, 0])
    return ToolSpec(name=name, kind="probe", config=cfg, body=name, contact_geoms=[tip, rod], joints=joints,
                    actuators=acts, home=np.asarray(cfg.position, dtype=float), frame=np.eye(3))


def add_grasper(spec: mujoco.MjSpec, cfg: GrasperConfig) -> ToolSpec:
    """Add the three-jaw grasper (paper 002) to ``spec``; return its :class:`ToolSpec`."""
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
    return ToolSpec(name=name, kind="grasper", config=cfg, body=name, contact_geoms=[shaft, *jaw_geoms],
                    joints=joints, actuators=acts, jaw_bodies=jaw_bodies, jaw_geoms=jaw_geoms, jaw_joints=jaw_joints,
                    jaw_actuator=jact, home=np.asarray(cfg.position, dtype=float), frame=rot)


def add_haptic_proxy(spec: mujoco.MjSpec, cfg: HapticProxyConfig, tool: ToolSpec) -> None:
    """Add a mocap body at ``tool``'s home pose and weld ``tool.body`` to it (virtual coupling)."""
    quat = _mat2quat(tool.frame)
    body = spec.worldbody.add_body(name=cfg.name, pos=tool.home.tolist(), quat=quat, mocap=True)
    body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.003, 0, 0], rgba=[0.2, 0.8, 0.2, 0.4],
                  contype=0, conaffinity=0, group=3)
    eq = f"{cfg.name}/coupling"
    spec.add_equality(name=eq, type=mujoco.mjtEq.mjEQ_WELD, name1=tool.body, name2=cfg.name,
                      objtype=mujoco.mjtObj.mjOBJ_BODY, solref=[cfg.timeconst, cfg.dampratio],
                      data=[0.0] * 3 + [0.0] * 3 + [1.0, 0.0, 0.0, 0.0] + [1.0, 0.0])
    tool.proxy = cfg.name
    tool.proxy_eq = eq
