"""Show a tissue model in MuJoCo: one flex per tissue surface, vertices on the world body.

The tissue's physics lives outside MuJoCo (no dofs). Its boundary surface becomes a MuJoCo flex
(``dim=2``) whose vertices all belong to the world body and which collides with nothing
(``contype = conaffinity = 0``), so it costs MuJoCo almost nothing. Before each
``Renderer.update_scene`` / viewer sync, :meth:`TissueBinding.write` copies the deformed surface
into ``d.flexvert_xpos``.

Two kinds of surface are shown:

* **smooth** (default when the tissue's volume carries the smooth surface it was meshed from,
  ``volume.source_surface = (vertices, faces)``, as the procedural organs do): the fine surface
  is embedded in the lattice tets (:mod:`surgsim_envs.geometry.embedding`) and its vertices are
  interpolated from the tet nodes every frame, so the organ looks smooth instead of showing the
  snapped lattice boundary, and still deforms with the tissue;
* **lattice**: the boundary triangles of the simulation mesh (``tissue.surface``), node by node.

Measured in MuJoCo 4.0: ``mjv_updateScene`` reads ``d.flexvert_xpos`` as it is (it does not
recompute it), while ``mj_forward``/``mj_step``/``mj_step1`` overwrite it with the rest positions
(world-body vertices do not move). So the write must come after the last MuJoCo call and right
before the scene update; :class:`~surgsim_envs.scene.simulation.Simulation.sync_visual` does that.
"""

from __future__ import annotations

import mujoco
import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.embedding import embed_points, interpolate
from surgsim_envs.scene.field_colors import COLORMAP_SIZE, FieldColors, colormap_rgb

VISUAL_MODES = ("auto", "smooth", "lattice")


def source_surface(tissue):
    """``(vertices (V,3) m, faces (F,3))`` of the smooth surface the tissue was meshed from, or None."""
    volume = getattr(tissue, "volume", None)
    src = getattr(volume, "source_surface", None)
    if src is None or len(getattr(volume, "tets", ())) == 0:
        return None
    return src


class TissueBinding:
    """The flex that shows one tissue model's surface.

    name: flex name in the MuJoCo model; tissue: a TissueModel (reads ``positions``,
    ``surface``, ``surface_nodes``, ``volume``); rgba: surface colour; visual: "auto" (smooth
    surface when the volume has a ``source_surface``, else the lattice surface), "smooth" (error
    if there is none) or "lattice"; render_field: None (plain colour) or a node field of the model
    (``tissue.field_names()``, e.g. "displacement", "stress") to colour the surface by
    (:mod:`surgsim_envs.scene.field_colors`), over ``render_range`` (lo, hi) or 0..max seen.
    """

    def __init__(self, name: str, tissue, rgba=(0.78, 0.33, 0.30, 1.0), visual: str = "auto",
                 render_field: str | None = None, render_range=None):
        if visual not in VISUAL_MODES:
            raise ConfigError(f"tissue '{name}': visual={visual!r}; choose one of {VISUAL_MODES}")
        self.name = name
        self.tissue = tissue
        self.rgba = [float(c) for c in rgba]
        self.vertadr = -1
        self.embedding = None
        src = source_surface(tissue) if visual != "lattice" else None
        if visual == "smooth" and src is None:
            raise ConfigError(f"tissue '{name}' has no smooth source surface to render (only procedural organs "
                              "and volumes with a source_surface do); use visual='lattice' or 'auto'")
        if src is not None:
            vertices, faces = np.asarray(src[0], dtype=np.float64), np.asarray(src[1], dtype=np.int64)
            self.embedding = embed_points(vertices, tissue.rest_positions, tissue.volume.tets)
            self.vertex_nodes = None
            self.elements = faces.reshape(-1, 3)
            self.n_vertices = len(vertices)
        else:
            surface = np.asarray(tissue.surface, dtype=np.int64)
            if surface.ndim != 2 or surface.shape[1] != 3 or len(surface) == 0:
                raise ConfigError(f"tissue '{name}' has no surface triangles to render (surface shape {surface.shape})")
            self.vertex_nodes = np.unique(surface)
            remap = -np.ones(len(tissue.positions), dtype=np.int64)
            remap[self.vertex_nodes] = np.arange(len(self.vertex_nodes))
            self.elements = remap[surface]
            self.n_vertices = len(self.vertex_nodes)
        self._buffer = np.zeros((self.n_vertices, 3))
        self.colors = None if render_field is None else FieldColors(tissue, render_field, render_range)
        self._texcoord = np.zeros((self.n_vertices, 2))
        self._model = None
        self.texcoordadr = -1

    def vertex_values(self, node_values: np.ndarray) -> np.ndarray:
        """(V,) a per-node scalar field (N,) at the flex vertices (interpolated on the smooth surface)."""
        f = np.asarray(node_values, dtype=np.float64)
        if self.embedding is not None:
            return np.einsum("vk,vk->v", self.embedding.weights, f[self.embedding.tet_nodes])
        return f[self.vertex_nodes]

    @property
    def smooth(self) -> bool:
        """True if the smooth embedded surface is shown (False: the lattice surface)."""
        return self.embedding is not None

    def vertex_positions(self) -> np.ndarray:
        """(V,3) m current flex vertex positions (a buffer reused by the next call)."""
        x = self.tissue.positions
        if self.embedding is not None:
            interpolate(np.ascontiguousarray(x), self.embedding.tet_nodes, self.embedding.weights, self._buffer)
        else:
            np.take(x, self.vertex_nodes, axis=0, out=self._buffer)
        return self._buffer

    def add_to(self, spec: mujoco.MjSpec) -> None:
        """Add the flex (at the tissue's current positions) to ``spec``."""
        flex = spec.add_flex()
        flex.name = self.name
        flex.dim = 2
        flex.vertbody = ["world"] * self.n_vertices
        flex.vert = self.vertex_positions().reshape(-1).tolist()
        flex.elem = self.elements.reshape(-1).tolist()
        flex.contype = 0
        flex.conaffinity = 0
        flex.radius = 0.0002
        flex.rgba = self.rgba
        flex.group = 0
        if self.colors is not None:   # colour map texture, one texture coordinate per vertex
            tex = spec.add_texture(name=f"{self.name}_colormap", type=mujoco.mjtTexture.mjTEXTURE_2D,
                                   width=COLORMAP_SIZE, height=1, nchannel=3)
            tex.data = colormap_rgb().tobytes()
            mat = spec.add_material(name=f"{self.name}_colormap")
            mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"{self.name}_colormap"
            flex.material = f"{self.name}_colormap"
            flex.rgba = [1.0, 1.0, 1.0, self.rgba[3]]
            self._texcoord[:, 0] = 0.01
            self._texcoord[:, 1] = 0.5
            flex.texcoord = self._texcoord.reshape(-1).tolist()

    def bind(self, m: mujoco.MjModel) -> None:
        """Find the flex's vertex block in the compiled model."""
        fid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_FLEX, self.name)
        if fid < 0:
            raise ConfigError(f"flex {self.name!r} not found in the compiled model")
        if int(m.flex_vertnum[fid]) != self.n_vertices:
            raise ConfigError(f"flex {self.name!r} has {m.flex_vertnum[fid]} vertices, expected {self.n_vertices}")
        self.vertadr = int(m.flex_vertadr[fid])
        if self.colors is not None:
            self._model = m
            self.texcoordadr = int(m.flex_texcoordadr[fid])

    def write(self, d: mujoco.MjData) -> None:
        """Write the current surface (m) into ``d.flexvert_xpos``: the tissue's surface nodes, or the
        smooth surface interpolated from its tets."""
        d.flexvert_xpos[self.vertadr:self.vertadr + self.n_vertices] = self.vertex_positions()
        if self.colors is not None and self._model is not None:
            values = self.vertex_values(self.tissue.node_field(self.colors.field))
            self.colors.coordinates(values, self._texcoord)
            self._model.flex_texcoord[self.texcoordadr:self.texcoordadr + self.n_vertices] = self._texcoord
