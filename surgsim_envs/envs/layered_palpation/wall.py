"""LayeredPalpation-v0's wall and probe, per tissue model the task accepts (:data:`WALL_MODELS`).

* ``layered`` (Lin et al. 2008, the task's premise): the layered lattice of
  :func:`surgsim_envs.geometry.anatomy.abdominal_wall_volume` (skin, fat, fascia, muscle,
  peritoneum), pressed by :class:`~surgsim_envs.contact.unilateral_probe.UnilateralProbe` (contact
  nodes pinned, the model's all-node ``static_solve`` per active-set iteration).
* ``fem_static``: the same wall as a continuum (linear tets with averaged nodal pressure, one
  Young's modulus and Poisson ratio per layer, elastic), on the layer-conforming lattice of
  :func:`surgsim_envs.geometry.wall_lattice.uniform_wall_volume`: x-y uniform at the task's
  ``spacing``, a node on every interface, each layer in equal cells of at most ``spacing``, the
  skin in cells of at most :data:`SKIN_CELL` (a 100 kPa skin on a 1 kPa fat bends as a plate: one
  linear tet through it locks). No fascia: it has no thickness (an interface material of the
  layered model). Pressed by :class:`~surgsim_envs.contact.compliant_unilateral_probe.
  CompliantUnilateralProbe`: the same unilateral frictionless contact law, solved on the
  prefactored stiffness's compliance block of the nodes under the probe (pinning nodes would
  refactorise the stiffness at each active-set iteration).
* ``fem_hex``: the same continuum on the same lattice, its box cells as hexahedra with incompatible
  bending modes (:mod:`surgsim_envs.tissue.fem_hex`): the skin bends as a plate on cells a linear
  tet cannot bend in, so a coarse lattice reads the reference's forces (docs/task_accuracy.md).
  The nodule is given at the cells' 8 Gauss points. Pressed as ``fem_static``.

The nodule rule is the task's for all three: the points where the elements sample their material
(``material_points()``: a tet's centroid, a hexahedron's Gauss points) within ``nodule_radius`` of
its centre get ``nodule_factor`` x their Young's modulus (``scale_material_at_points``), the centre
at the median height of the fat's tets. Units: m, N.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

#: the models LayeredPalpation-v0 builds its wall with
WALL_MODELS = ("layered", "fem_static", "fem_hex")
#: the wall models built as a continuum on :func:`continuum_volume`'s lattice
CONTINUUM_MODELS = ("fem_static", "fem_hex")
#: m, the tallest skin cell of the fem_static wall: 2 cells through the 2 mm skin
SKIN_CELL = 0.001
#: MB of cached compliance columns of the fem_static wall (72 x nodes bytes per contact node)
CACHE_MB = 500.0

_VOLUMES: dict = {}


@dataclass
class Wall:
    """A built wall: ``tissue``, its ``top`` surface nodes, ``z_top`` m, the tets' ``centroids`` and
    the ``fat_z`` centroid heights of the fat's tets; ``probe`` (``nodes``, ``last_iterations``,
    ``force()``); ``press(centre)`` solves a press; ``lift()`` takes the probe off before the reset's
    ``tissue.reset()``; ``ready()`` prepares the tissue after a reset; ``organ`` what the render scene
    builds (module :mod:`.scene`)."""

    tissue: object
    top: np.ndarray
    z_top: float
    centroids: np.ndarray
    fat_z: np.ndarray
    probe: object
    press: Callable
    lift: Callable
    #: called after the nodule is placed, before the first press (e.g. factorise a stiffness)
    ready: Callable = lambda: None
    #: the scene organ that mirrors the wall for rendering (None: the registered abdominal wall at the spacing)
    organ: object = None


def layered_wall(cfg) -> Wall:
    from surgsim_envs.contact.unilateral_probe import UnilateralProbe
    from surgsim_envs.geometry.anatomy import abdominal_wall_volume
    from surgsim_envs.tissue import make

    key = ("layered", tuple(float(v) for v in cfg.size), float(cfg.spacing))
    if key not in _VOLUMES:
        _VOLUMES[key] = abdominal_wall_volume(cfg.spacing, size=key[1])
    vol = _VOLUMES[key]
    bottom = vol.face_nodes(4)  # no node below: the whole bottom face
    tissue = make("layered", vol, fixed=bottom)
    top = np.flatnonzero(vol.neighbours[:, 5] < 0)
    probe = UnilateralProbe(tissue, top, cfg.probe_radius)
    centroids = tissue.element_centroids()
    fat = vol.layer_names.index("fat")
    return Wall(tissue, top, float(vol.nodes[top, 2].max()), centroids, centroids[vol.labels == fat, 2], probe,
                lambda centre: probe.press(centre, tissue.static_solve), lambda: probe.move_to((1e3, 1e3, 1e3)))


def continuum_volume(cfg):
    """The fem_static wall's lattice and its layer planes (module docstring)."""
    from surgsim_envs.geometry.anatomy import ABDOMINAL_WALL_THICKNESS
    from surgsim_envs.geometry.wall_lattice import layer_planes, uniform_wall_volume

    planes = layer_planes(ABDOMINAL_WALL_THICKNESS)
    key = ("continuum", tuple(float(v) for v in cfg.size), float(cfg.spacing))
    if key not in _VOLUMES:
        _VOLUMES[key] = uniform_wall_volume(key[1], planes, float(cfg.spacing), min(SKIN_CELL, float(cfg.spacing)))
    return _VOLUMES[key], planes


def continuum_wall(cfg, model: str = "fem_static") -> Wall:
    """The wall as a continuum of ``model`` (one of :data:`CONTINUUM_MODELS`) on :func:`continuum_volume`."""
    from surgsim_envs.contact.compliant_unilateral_probe import CompliantUnilateralProbe
    from surgsim_envs.geometry.anatomy import ANATOMY_MATERIALS
    from surgsim_envs.materials import PRESETS
    from surgsim_envs.tissue import make

    vol, planes = continuum_volume(cfg)
    table = {**PRESETS, **ANATOMY_MATERIALS}
    mats = {k: table[name].replace(relax_fraction=0.0, friction=0.0) for k, (name, _, _) in enumerate(planes)}
    z_top = float(vol.nodes[:, 2].max())
    bottom = np.flatnonzero(vol.nodes[:, 2] <= 1e-9 * z_top)
    tissue = make(model, vol, mats[0], fixed=bottom, region_materials=mats, solver="auto", cache_mb=CACHE_MB)
    top = np.flatnonzero(vol.nodes[:, 2] >= z_top * (1 - 1e-9))
    probe = CompliantUnilateralProbe(tissue, top, cfg.probe_radius)
    centroids = tissue.element_centroids()           # tets (fem_static) or box cells (fem_hex)
    # each element's layer: the heights of the layers' planes classify the centroids alike for both
    bottoms = np.array([lo for _, lo, _ in planes])
    layer = np.clip(np.searchsorted(bottoms, centroids[:, 2], side="right") - 1, 0, len(planes) - 1)
    fat = [name for name, _, _ in planes].index("fat")
    # lift() runs right before the reset's tissue.reset(), which sets the rest state: the probe only
    # forgets its contact (solving the unloaded equilibrium there would factorise the stiffness of the
    # last episode's nodule, only for ready() to factorise the new one)
    return Wall(tissue, top, z_top, centroids, centroids[layer == fat, 2], probe, probe.press,
                probe.clear, ready=tissue.compliance, organ=vol)


def hex_wall(cfg) -> Wall:
    """The continuum wall on hexahedra with incompatible modes (module docstring)."""
    return continuum_wall(cfg, "fem_hex")


BUILDERS = {"layered": layered_wall, "fem_static": continuum_wall, "fem_hex": hex_wall}


def wall_nodes(model: str, size, spacing: float) -> int:
    """Nodes of the wall ``model`` builds on a patch of ``size`` (x, y) m at ``spacing`` m (an estimate
    for the layered lattice, exact for the continuum's), before building it."""
    import math

    from surgsim_envs.geometry.anatomy import ABDOMINAL_WALL_THICKNESS

    cols = (size[0] / spacing + 1) * (size[1] / spacing + 1)
    if model not in CONTINUUM_MODELS:
        return int(cols * (0.029 / spacing + 1))
    th = list(ABDOMINAL_WALL_THICKNESS.values())
    levels = 1 + math.ceil(th[0] / min(SKIN_CELL, spacing) - 1e-3) + sum(math.ceil(t / spacing - 1e-3) for t in th[1:])
    return int(cols * levels)


__all__ = ["WALL_MODELS", "CONTINUUM_MODELS", "SKIN_CELL", "Wall", "BUILDERS", "layered_wall", "continuum_wall",
           "hex_wall", "continuum_volume", "wall_nodes"]
