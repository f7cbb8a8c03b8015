"""A converged force reference for LayeredPalpation-v0's presses: quasi-static FEM on the wall's layers.

The task presses a rigid sphere into an abdominal wall patch (:func:`surgsim_envs.geometry.anatomy.
abdominal_wall_layers`: skin 2 mm, fat 15 mm, muscle 10 mm, peritoneum 2 mm, flat, the whole
bottom bonded, the sides free) with a 30x stiffer nodule in the fat. The reference solves the
same presses as a continuum: ``fem_static`` (linear tets, averaged nodal pressure) with each
tet's Young's modulus and Poisson ratio from the layer its centroid lies in, the nodule's tets
(centroid within the nodule's radius of its centre, the task's own rule) at ``nodule_factor`` x
theirs, and the contact of :mod:`surgsim_envs.bench.task_reference` (stiffness per unit area,
surface samples at half the spacing), frictionless as the task's probe is.

The lattice (:func:`wall_volume`) is a box of Kuhn cells on three node axes:

* x and y graded about the press site (:func:`surgsim_envs.geometry.graded_axis.graded_axis`):
  spacing ``fine`` within 15 mm of it (:data:`surgsim_envs.geometry.wall_lattice.FINE_HALF_WIDTH`),
  growing by :data:`task_reference.GROWTH` per cell to :data:`task_reference.COARSE_SPACING`;
* z conforming to the layers: a node on every interface (27, 12 and 2 mm above the bed), the
  skin cut into cells of at most ``fine / 2`` (a 100 kPa skin on a 1 kPa fat bends as a plate:
  one linear tet through it locks), the fat graded from that size at the skin down to the coarse
  spacing, the muscle and peritoneum at the coarse spacing.

The fascia of the layered model is an interface material (springs between the nodes snapped onto
the fat/muscle interface, no thickness and no tets), so the continuum has none, as in the layered
accuracy bench (docs/models/layered.md). Only ``fine`` is refined (by 1/sqrt 2); the coarse
lattice and the growth stay. Units: m, Pa, N.
"""

from __future__ import annotations

import math
import time
from types import SimpleNamespace
from typing import Sequence

import numpy as np

from surgsim_envs.bench import task_reference
from surgsim_envs.bench.memory_need import require_memory
from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.wall_lattice import (SKIN_CELL_FRACTION, graded_wall_volume,  # noqa: F401
                                               layer_planes, wall_z_axis)

#: MB of cached compliance columns: a press at h_f 1 mm (48,300 nodes) ran within 800 MB (230 columns),
#: one at 0.71 mm (107,520 nodes) peaked at 16.6 GB in all;
#: task_reference's 4,000 MB let one process reach 9.5 GB at that level, more than a shared host had free
CACHE_MB = 1000.0
#: (nodes, bytes): the peak resident memory of one press site's reference solve (`/usr/bin/time -v`, MKL
#: PARDISO, one site per process) at h_f 2 and 0.71 mm; :func:`peak_memory` interpolates a power law
PEAK_MEMORY = ((11_600, 1.15e9), (107_520, 16.6e9))
#: s and m/s: the quasi-static load stepping of a reference press (the probe moves 0.2 mm per step)
DT = 1e-3
PROBE_SPEED = 0.2
HOVER = 0.002


def wall_volume(size, planes, site, fine: float, nodule_centre, nodule_radius: float,
                coarse: float = task_reference.COARSE_SPACING, ratio: float = task_reference.GROWTH):
    """The reference lattice of a press at ``site`` (x, y) m on a wall patch of ``size`` (x, y) m
    centred on the origin, bed at z = 0 (:func:`surgsim_envs.geometry.wall_lattice.graded_wall_volume`):
    tet labels are the layer index (``planes`` order) for plain tets and ``len(planes)`` + the layer
    index for the nodule's tets (centroid within ``nodule_radius`` of ``nodule_centre``)."""
    return graded_wall_volume(size, planes, site, fine, nodule_centre, nodule_radius, coarse, ratio)


def peak_memory(nodes: int) -> float:
    """The expected peak memory (bytes) of one press site's solve on a lattice of ``nodes`` nodes: the
    power law through :data:`PEAK_MEMORY` (exponent 1.2: the factorisation's fill grows faster than
    the nodes)."""
    (n0, m0), (n1, m1) = PEAK_MEMORY
    return m1 * (float(nodes) / n1) ** (math.log(m1 / m0) / math.log(n1 / n0))


def require_site_memory(task: str, volume, fine: float, site: str) -> None:
    """ConfigError, before the solve, when the press at ``site`` on ``volume`` would need more memory
    than this host has available (:func:`surgsim_envs.bench.memory_need.require_memory`)."""
    require_memory(peak_memory(len(volume.nodes)),
                   f"{task}: the reference at fine spacing {fine * 1e3:.3g} mm ({len(volume.nodes)} nodes at the "
                   f"{site} site)",
                   "Run the quick set (surgsim bench task-accuracy --quick), or this level one press site per "
                   "process on a host with more memory (surgsim_envs.bench.probe_sets.layered_palpation."
                   "reference_row(TASK, FULL, fine, sites=('mirror',))); the shipped table "
                   "(surgsim_envs/tissue/data/task_accuracy_table.json) holds its forces.")


def region_materials(planes, materials: dict, nodule_factor: float) -> dict:
    """{label: Material} of :func:`wall_volume`'s labels: each layer's material elastic and frictionless
    (the task's probe has no friction), the nodule's at ``nodule_factor`` x the layer's modulus."""
    out = {}
    for k, (name, _, _) in enumerate(planes):
        m = materials[name].replace(relax_fraction=0.0, friction=0.0)
        out[k] = m
        out[len(planes) + k] = m.replace(young=m.young * float(nodule_factor), name=f"{name} nodule")
    return out


def nodule_centre_z(planes, layer: str, radius: float) -> float:
    """The task's nodule height (m above the bed) in the continuum: the middle of ``layer`` (the
    median of its tets' centroid heights), at least ``radius / 2`` above its bottom."""
    lo, hi = next((a, b) for n, a, b in planes if n == layer)
    return float(np.clip(0.5 * (lo + hi), lo + radius / 2, hi))


def press_scene(volume, materials: dict, site, tip_radius: float, fine: float, top: float):
    """A Simulation of ``volume`` (``fem_static``, bed bonded, ``materials`` per label) and a
    position-driven frictionless probe of ``tip_radius`` hovering over ``site``, with the reference
    contact (:data:`task_reference.CONTACT_STIFFNESS_PER_AREA` x ``fine``^2 per node, samples at
    ``fine`` / 2)."""
    from surgsim_envs.scene import Simulation, build_scene
    from surgsim_envs.scene.config import ContactConfig, ProbeConfig, SceneConfig, TissueConfig

    lo, hi = volume.bounds()
    tissue = TissueConfig(name="wall", organ=volume, model=task_reference.REFERENCE_MODEL, material=materials[0],
                          spacing=None, anchors=("bottom",), position=tuple((lo + hi) / 2.0),
                          region_materials=dict(materials),
                          options={**task_reference.REFERENCE_OPTIONS, "cache_mb": CACHE_MB})
    probe = ProbeConfig(name="probe", tip_radius=float(tip_radius), friction=0.0,
                        position=(float(site[0]), float(site[1]), top + tip_radius + 2 * HOVER))
    contact = ContactConfig(stiffness=task_reference.CONTACT_STIFFNESS_PER_AREA * float(fine) ** 2,
                            tangential_stiffness=None, surface_samples=task_reference.SURFACE_SUBDIVISIONS)
    cfg = SceneConfig(name="layered_press_reference", tissues=[tissue], tools=[probe], contact=contact, dt=DT,
                      gravity=(0.0, 0.0, 0.0))
    return Simulation(build_scene(cfg), dt=DT)


def site_forces(volume, materials: dict, site, depths: Sequence[float], tip_radius: float, fine: float,
                top: float) -> list[float]:
    """The reference force (N) of a straight-down press at ``site`` at each of ``depths`` (m below the
    rest surface ``top``, rising), read in one quasi-static descent
    (:func:`task_reference.descent_forces`)."""
    sim = press_scene(volume, materials, site, tip_radius, fine, top)
    env = SimpleNamespace(sim=sim, surface_z=float(top),
                          config=SimpleNamespace(tip_radius=float(tip_radius), hover=HOVER, probe_speed=PROBE_SPEED))
    return task_reference.descent_forces(env, site, depths)


def reference_row(task: str, sites: dict, depths: Sequence[float], fine: float, *, size, thickness: dict,
                  materials: dict, nodule_xy, nodule_radius: float, nodule_factor: float, nodule_layer: str,
                  tip_radius: float, coarse: float = task_reference.COARSE_SPACING) -> dict:
    """The reference forces at fine spacing ``fine`` (m) of straight-down presses at each of
    ``sites`` ({name: (x, y) m}) to each of ``depths`` (m), one graded lattice per site; keys
    ``"0/<site>/<depth>mm"`` as :func:`surgsim_envs.bench.task_accuracy.measure`'s; ``coarse``: the
    spacing (m) away from the press site."""
    from surgsim_envs.tissue import TissueUnstableError

    if not all(a < b for a, b in zip(depths, depths[1:])):
        raise ConfigError(f"reference depths must rise, got {list(depths)} m")
    planes = layer_planes(thickness)
    top = planes[-1][2]
    centre = (float(nodule_xy[0]), float(nodule_xy[1]), nodule_centre_z(planes, nodule_layer, nodule_radius))
    mats = region_materials(planes, materials, nodule_factor)
    t0 = time.perf_counter()
    forces, nodes = {}, {}
    for name, xy in sites.items():
        vol = wall_volume(size, planes, xy, fine, centre, nodule_radius, coarse=coarse)
        nodes[name] = int(len(vol.nodes))
        require_site_memory(task, vol, fine, name)
        try:
            values = site_forces(vol, mats, xy, depths, tip_radius, fine, top)
        except TissueUnstableError as exc:
            raise ConfigError(f"{task}: the reference {task_reference.REFERENCE_MODEL} at {fine * 1e3:.3g} mm failed: "
                              f"{str(exc).splitlines()[0]}") from None
        for depth, f in zip(depths, values):
            forces[f"0/{name}/{depth * 1e3:g}mm"] = f
    return {"task": task, "model": task_reference.REFERENCE_MODEL, "spacing": float(fine),
            "coarse_spacing": float(coarse), "nodes": max(nodes.values()), "nodes_by_site": nodes,
            "forces_N": forces, "seconds": time.perf_counter() - t0, "nodule_centre": list(centre)}


__all__ = ["PEAK_MEMORY", "peak_memory", "require_site_memory", "layer_planes", "wall_z_axis", "wall_volume",
           "region_materials", "nodule_centre_z", "press_scene", "site_forces", "reference_row"]
