"""Show a tissue model in MuJoCo: one flex per tissue surface, vertices on the world body.

The tissue's physics lives outside MuJoCo (no dofs). Its boundary surface becomes a MuJoCo flex
(``dim=2``) whose vertices all belong to the world body and which collides with nothing
(``contype = conaffinity = 0``), so it costs MuJoCo almost nothing. Before each
``Renderer.update_scene`` / viewer sync, :meth:`TissueBinding.write` copies the deformed surface
node positions into ``d.flexvert_xpos``.

Measured in MuJoCo 4.0: ``mjv_updateScene`` reads ``d.flexvert_xpos`` as it is (it does not
recompute it), while ``mj_forward``/``mj_step``/``mj_step1`` overwrite it with the rest positions
(world-body vertices do not move). So the write must come after the last MuJoCo call and right
before the scene update; :class:`~surgsim_envs.scene.simulation.Simulation.sync_visual` does that.
"""

from __future__ import annotations

import mujoco
import numpy as np

from surgsim_envs.errors import ConfigError


class TissueBinding:
    """The flex that shows one tissue model's surface.

    name: flex name in the MuJoCo model; tissue: a TissueModel (reads ``positions``,
    ``surface``, ``surface_nodes``); rgba: surface colour.
    """

    def __init__(self, name: str, tissue, rgba=(0.78, 0.33, 0.30, 1.0)):
        self.name = name
        self.tissue = tissue
        surface = np.asarray(tissue.surface, dtype=np.int64)
        if surface.ndim != 2 or surface.shape[1] != 3 or len(surface) == 0:
            raise ConfigError(f"tissue '{name}' has no surface triangles to render (surface shape {surface.shape})")
        self.vertex_nodes = np.unique(surface)
        remap = -np.ones(len(tissue.positions), dtype=np.int64)
        remap[self.vertex_nodes] = np.arange(len(self.vertex_nodes))
        self.elements = remap[surface]
        self.rgba = [float(c) for c in rgba]
        self.vertadr = -1

    def add_to(self, spec: mujoco.MjSpec) -> None:
        """Add the flex (at the tissue's current positions) to ``spec``."""
        flex = spec.add_flex()
        flex.name = self.name
        flex.dim = 2
        flex.vertbody = ["world"] * len(self.vertex_nodes)
        flex.vert = self.tissue.positions[self.vertex_nodes].reshape(-1).tolist()
        flex.elem = self.elements.reshape(-1).tolist()
        flex.contype = 0
        flex.conaffinity = 0
        flex.radius = 0.0002
        flex.rgba = self.rgba
        flex.group = 0

    def bind(self, m: mujoco.MjModel) -> None:
        """Find the flex's vertex block in the compiled model."""
        fid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_FLEX, self.name)
        if fid < 0:
            raise ConfigError(f"flex {self.name!r} not found in the compiled model")
        if int(m.flex_vertnum[fid]) != len(self.vertex_nodes):
            raise ConfigError(f"flex {self.name!r} has {m.flex_vertnum[fid]} vertices, expected {len(self.vertex_nodes)}")
        self.vertadr = int(m.flex_vertadr[fid])

    def write(self, d: mujoco.MjData) -> None:
        """Copy the tissue's surface node positions (m) into ``d.flexvert_xpos``."""
        n = len(self.vertex_nodes)
        d.flexvert_xpos[self.vertadr:self.vertadr + n] = self.tissue.positions[self.vertex_nodes]
