"""What every tool kind shares: the :class:`ToolSpec` record and MjSpec helpers.

A tool kind (probe, three-jaw grasper, ... ) is ONE module in this package that owns its MjSpec
build, its commands and readouts, and registers itself (:mod:`surgsim_envs.scene.tools`). Its
``build(spec, cfg)`` adds the tool to a spec and returns a :class:`ToolSpec` (or a subclass with
the kind's commands) recording the MuJoCo names of its bodies, contact geoms, joints and
actuators; :meth:`ToolSpec.bind` resolves them to ids after compilation. The step loop
(:class:`~surgsim_envs.scene.Simulation`) sees only this base interface. Units: m, kg, N, rad.

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

from surgsim_envs.errors import ConfigError

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
    (columns are the slide axes in world coordinates). rounded_geoms: box geoms among
    ``contact_geoms`` that the tissue contact treats as rounded boxes (every edge rounded to the box's
    thinnest half extent, :data:`surgsim_envs.contact.ROUNDED_BOX`; MuJoCo keeps the plain box).
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
    rounded_geoms: list[str] = field(default_factory=list)
    # ids, filled by bind()
    body_id: int = -1
    geom_ids: np.ndarray | None = None
    dof_adr: np.ndarray | None = None
    qpos_adr: np.ndarray | None = None
    actuator_ids: np.ndarray | None = None
    jaw_body_ids: np.ndarray | None = None
    jaw_geom_ids: np.ndarray | None = None
    rounded_geom_ids: np.ndarray | None = None
    jaw_qpos_adr: np.ndarray | None = None
    jaw_actuator_id: int = -1
    mocap_id: int = -1
    proxy_eq_id: int = -1

    # -- hooks a tool kind may override --------------------------------------------------------
    @property
    def contact_feature_radius(self) -> float | None:
        """Smallest contact feature (m), e.g. a probe's tip radius: the scene embeds surface contact
        points in the tissue when a feature is smaller than the lattice spacing (None = no limit)."""
        return None

    def actuator_rates(self) -> dict[int, float]:
        """{actuator id: default rate limit of its target (m/s or rad/s)} after :meth:`bind`."""
        return {int(a): float(getattr(self.config, "speed", math.inf)) for a in self.actuator_ids}

    def set_grip(self, sim, value: float, speed: float | None = None) -> None:
        """Grip command in [0, 1] (0 open, 1 closed) from a haptic device or script; tools without
        jaws ignore it."""

    @property
    def has_grip(self) -> bool:
        """True if :meth:`set_grip` does something (the tool has jaws)."""
        return False

    def require(self, command: str) -> None:
        """ConfigError naming the tool, its kind and ``command`` if this kind has no such command."""
        if not callable(getattr(self, command, None)):
            raise ConfigError(f"tool '{self.name}' is a {self.kind}; it has no command {command!r}")

    def bind(self, m: mujoco.MjModel) -> None:
        """Resolve names to ids in the compiled model ``m``."""
        def oid(kind, name):
            return mujoco.mj_name2id(m, kind, name)

        self.body_id = oid(mujoco.mjtObj.mjOBJ_BODY, self.body)
        self.geom_ids = np.array([oid(mujoco.mjtObj.mjOBJ_GEOM, g) for g in self.contact_geoms], dtype=np.int64)
        unknown = sorted(set(self.rounded_geoms) - set(self.contact_geoms))
        if unknown:
            raise ConfigError(f"tool '{self.name}': rounded_geoms {unknown} are not among its contact geoms "
                              f"{self.contact_geoms}")
        self.rounded_geom_ids = np.array([oid(mujoco.mjtObj.mjOBJ_GEOM, g) for g in self.rounded_geoms], dtype=np.int64)
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


