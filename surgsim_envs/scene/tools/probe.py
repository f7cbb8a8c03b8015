"""The probe: a rigid rod with a spherical tip (indenter). One tool kind = this module + registration.

The body origin is the centre of the spherical tip; the rod (capsule) runs up the body's +z
axis. Slide joints x, y, z (world axes) with position actuators; optional hinges about x and y
for tilt. ``qpos`` of a slide joint is the displacement from home. Units: m, kg, N, rad.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.scene.config import ProbeConfig, rate_limit, vec
from surgsim_envs.scene.tools.base import _HINGE, TOOL_CONAFFINITY, TOOL_CONTYPE, ToolSpec, _slide_drive
from surgsim_envs.validate import positive

KIND = "probe"
DRIVES = ("position", "proxy", "free")


@dataclass
class ProbeTool(ToolSpec):
    """A built probe: the tip radius limits how coarse the tissue contact sampling may be."""

    @property
    def contact_feature_radius(self) -> float:
        return float(self.config.tip_radius)


def validate(p: ProbeConfig) -> None:
    """ConfigError naming the first bad field of probe ``p``."""
    for key, hint in (("tip_radius", "e.g. 0.005 (5 mm)"), ("rod_radius", "e.g. 0.003"), ("rod_length", "e.g. 0.1"),
                      ("kp", "e.g. 2e4 N/m"), ("mass", "e.g. 0.05 kg"), ("travel", "e.g. 0.2 m")):
        positive(getattr(p, key), f"probe '{p.name}' {key}", fix=hint)
    rate_limit(p.speed, f"probe '{p.name}' speed")
    vec(p.position, 3, f"probe '{p.name}' position")
    if p.drive not in DRIVES:
        raise ConfigError(f"probe '{p.name}' drive={p.drive!r}; choose 'position', 'proxy' or 'free'")


def build(spec: mujoco.MjSpec, cfg: ProbeConfig) -> ToolSpec:
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
    return ProbeTool(name=name, kind=KIND, config=cfg, body=name, contact_geoms=[tip, rod], joints=joints,
                    actuators=acts, home=np.asarray(cfg.position, dtype=float), frame=np.eye(3))


