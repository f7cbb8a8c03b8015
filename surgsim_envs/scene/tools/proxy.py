"""The haptic proxy: a mocap body a device or script moves, welded to a tool (virtual coupling).

The proxy sits at the tool's home pose; the weld's constraint force is the force the hand feels
(:meth:`surgsim_envs.scene.Simulation.proxy_force`).
"""

from __future__ import annotations

import mujoco

from surgsim_envs.scene.config import HapticProxyConfig
from surgsim_envs.scene.tools.base import ToolSpec, _mat2quat


def build(spec: mujoco.MjSpec, cfg: HapticProxyConfig, tool: ToolSpec) -> None:
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
