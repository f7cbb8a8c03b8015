"""LayeredPalpation-v0's probe set: straight-down presses over the nodule and at its mirror site.

The task's scene is its own (``gym.make("SurgSim/LayeredPalpation-v0", spacing=...)``): the
abdominal wall patch (8 x 6 cm, skin / fat / fascia / muscle / peritoneum, bed bonded), the 5 mm
frictionless unilateral probe and one equilibrium solve per press (quasi-static: no time step).
The nodule is the task's (30x the Young's modulus at the element points within 8 mm of its centre,
``material_points``: tets' centroids, hexahedra's Gauss points; at the middle of the fat), placed by the reset option ``nodule_position`` at (2, 1) cm; the mirror site
is (-2, -1) cm. Both sites lie on a node of every lattice the task builds at the spacings below
(multiples of 10 mm from the patch's edges) and of the reference's (graded about each site).

Each press is one env step from a fresh reset, to 2.5, 3.5 and 4.5 mm: under the probe's radius,
and away from the depths at which a lattice node at the footprint's edge joins the contact (at a
spacing h, a node at distance rho joins at depth r - sqrt(r^2 - rho^2): 2.76 mm for rho = 4.47 mm
at h = 2 mm, 5 mm for rho = r), so no reading sits on that edge.

Models: the task builds its wall as ``layered`` (the paper's model, the task's premise: its
unilateral probe solves each press with the model's all-node ``static_solve``) or as a continuum
on a layer-conforming lattice, ``fem_hex`` (its default, hexahedra) or ``fem_static`` (tets), the
same contact law solved on the prefactored stiffness's compliance; every other model is reported as
refused, with that reason. Rows at the spacings 10, 5, 4, 3.33, 2.5 and 2 mm.

Between the nodes: the presses over the nodule again, with the nodule and the press moved by half the
row's spacing in x and in y (the middle of a lattice cell), keyed ``0/over-offnode/<depth>``. A
press lands anywhere on the lattice in the task, and on a coarse lattice its force depends on where
(the contact's footprint meets a different set of nodes, and the nodule's cells change). They are
scored against the reference's presses over the nodule (:func:`reference_key`): the reference's
force over the nodule does not depend on where the nodule sits to about 1 % (its 1 mm levels at
(2, 1) and (-1.5, 0.5) cm differ by 1.0-1.1 %), so the shift's reference is the unshifted one.

Path independence: the force at the nodule site at the middle depth after a press 6 mm away in
the same episode, against the same press from a fresh reset (the probe claims the force depends
on the pose only). Unilateral: the largest pulling force the probe reports before the env clips
it at 0. Reference: :mod:`surgsim_envs.bench.layered_reference`.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from surgsim_envs.bench.probe_set import Inclusion, ProbeSet, mirror
from surgsim_envs.errors import ConfigError

TASK = "SurgSim/LayeredPalpation-v0"
#: the models the task accepts (its env builds no other)
MODELS = ("layered", "fem_static", "fem_hex")
REFUSAL = ("the task builds its wall with the layered model (the paper's springs), fem_static or fem_hex (the continuum "
           "on a layer-conforming lattice, in tets or hexahedra) only: its option model= takes no other")
#: m, the nodule's centre (x, y): a node of every lattice the probe set uses
NODULE_XY = (0.02, 0.01)
#: how the reference is described in the task-accuracy table
REFERENCE_DESCRIPTION = ("`fem_static` on the wall's flat layers (per-tet E and nu of skin, fat, muscle, peritoneum; "
                         "the nodule's tets 30x; no fascia: it has no thickness), elastic and frictionless as the "
                         "task's probe, contact stiffness 1e+08 N/m^3 per area, surface samples at half the spacing, "
                         "the skin in cells of half the fine spacing")
#: m, how far from the nodule site the press before the path-independence press is
PATH_OFFSET = 0.006
#: the site name of the presses between the nodes (module docstring)
OFF_NODE = "over-offnode"


def _nodule() -> Inclusion:
    """The task's default nodule at :data:`NODULE_XY` (radius, factor and depth from its config and anatomy)."""
    from surgsim_envs.bench import layered_reference as ref
    from surgsim_envs.envs.layered_palpation import LayeredPalpationConfig
    from surgsim_envs.geometry.anatomy import ABDOMINAL_WALL_THICKNESS

    cfg = LayeredPalpationConfig()
    planes = ref.layer_planes(ABDOMINAL_WALL_THICKNESS)
    depth = planes[-1][2] - ref.nodule_centre_z(planes, "fat", cfg.nodule_radius)
    return Inclusion(f"{cfg.nodule_factor:g}x nodule, r {cfg.nodule_radius * 1e3:g} mm, {depth * 1e3:.3g} mm deep",
                     NODULE_XY, depth, cfg.nodule_radius, cfg.nodule_factor)


NODULE = _nodule()
FULL = ProbeSet(inclusions=(NODULE,), depths=(0.0025, 0.0035, 0.0045), hold=0.0,
                spacings=(0.01, 0.005, 0.004, 0.01 / 3, 0.0025, 0.002),
                reference_spacings=(0.002, 0.002 / math.sqrt(2), 0.001, 0.001 / math.sqrt(2)))
QUICK = ProbeSet(inclusions=(NODULE,), depths=(0.0025, 0.0045), hold=0.0, spacings=(0.005,),
                 reference_spacings=(0.004, 0.004 / math.sqrt(2), 0.002))


class Presser:
    """Presses of a LayeredPalpation-v0 env (unwrapped): one env step each, the action built from
    the site (m) and depth (m); records the wall time per step and the largest pulling force."""

    def __init__(self, env):
        self.env = env
        self.half = 0.5 * np.asarray(env.config.size, dtype=float)
        self.max_depth = float(env.config.max_depth)
        self.step_us: list[float] = []
        self.max_tensile = 0.0

    def press(self, xy, depth: float) -> float:
        if not 0.0 <= depth <= self.max_depth:
            raise ConfigError(f"{TASK}: probe depth {depth!r} m is outside the task's [0, {self.max_depth:g}] m; "
                              "press shallower or raise max_depth")
        action = np.array([xy[0] / self.half[0], xy[1] / self.half[1], 2.0 * depth / self.max_depth - 1.0, -1.0])
        t0 = time.perf_counter()
        _, _, _, _, info = self.env.step(action.astype(np.float32))
        self.step_us.append((time.perf_counter() - t0) * 1e6)
        raw = float(self.env.probe.force()[2])      # before the env reads a round-off below 0 as 0
        self.max_tensile = max(self.max_tensile, -raw)
        return float(info["force_N"])

    def fresh(self, inclusion: Inclusion, xy, depth: float) -> float:
        """A press from a fresh reset with the nodule at ``inclusion.position``."""
        self.env.reset(seed=0, options={"nodule_position": tuple(inclusion.position)})
        return self.press(xy, depth)


def _check_nodule(env, inclusion: Inclusion) -> None:
    cfg = env.config
    if (cfg.nodule_radius, cfg.nodule_factor) != (inclusion.radius, inclusion.contrast):
        raise ConfigError(f"{TASK}: the probe set's nodule (radius {inclusion.radius} m, factor {inclusion.contrast}) "
                          f"is not the task's (radius {cfg.nodule_radius} m, factor {cfg.nodule_factor})")


def measure(task: str, model: str, spacing: float, probes: ProbeSet) -> dict:
    """One row: ``probes`` pressed in the task's scene built at ``spacing`` (m) (see the module docstring)."""
    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401  (registers the tasks)

    head = {"task": task, "model": model, "spacing": float(spacing)}
    if model not in MODELS:
        return {**head, "refused": REFUSAL}
    env = gym.make(task, model=model, spacing=float(spacing), disable_env_checker=True).unwrapped
    presser = Presser(env)
    forces = {}
    for i, inc in enumerate(probes.inclusions):
        _check_nodule(env, inc)
        for site in ("over", "mirror"):
            xy = inc.position if site == "over" else mirror(inc.position)
            for depth in probes.depths:
                forces[f"{i}/{site}/{depth * 1e3:g}mm"] = presser.fresh(inc, xy, depth)
        half = 0.5 * float(spacing)
        moved = dataclasses.replace(inc, position=(inc.position[0] + half, inc.position[1] + half))
        for depth in probes.depths:
            forces[f"{i}/{OFF_NODE}/{depth * 1e3:g}mm"] = presser.fresh(moved, moved.position, depth)
    inc, depth = probes.inclusions[0], probes.depths[len(probes.depths) // 2]
    straight = presser.fresh(inc, inc.position, depth)
    presser.press((inc.position[0] - PATH_OFFSET, inc.position[1]), depth)
    after = presser.press(inc.position, depth)
    row = {**head, "nodes": int(env.tissue.n_nodes), "forces_N": forces, "max_tensile_N": presser.max_tensile,
           # the mean over the presses: a press at a site not pressed before costs what a cached one
           # does not (fem_static back-substitutes the compliance of the nodes under the probe)
           "us_per_env_step": float(np.mean(presser.step_us)),
           "us_per_env_step_median": float(np.median(presser.step_us)),
           "us_per_env_step_max": float(np.max(presser.step_us)), "control_dt": float(env.control_dt),
           "dt": float(env.control_dt), "path_difference": abs(after - straight) / max(abs(straight), 1e-12),
           "nodule_centre": [float(v) for v in env.nodule]}
    env.close()
    row["us_per_ms"] = row["us_per_env_step"] / (row["control_dt"] * 1e3)
    return row


def reference_key(key: str) -> str:
    """The reference press a row's press ``key`` is scored against: a press between the nodes
    against the reference's press over the nodule at the same depth (module docstring)."""
    return key.replace(f"/{OFF_NODE}/", "/over/")


def check_reference_memory(task: str, probes: ProbeSet) -> None:
    """ConfigError, before any level runs, when the finest reference level of ``probes`` would need more
    memory than this host has available (its lattice at the nodule site: every site's has as many
    nodes, :func:`surgsim_envs.bench.layered_reference.require_site_memory`)."""
    from surgsim_envs.bench import layered_reference
    from surgsim_envs.envs.layered_palpation import LayeredPalpationConfig
    from surgsim_envs.geometry.anatomy import ABDOMINAL_WALL_THICKNESS

    if not probes.reference_spacings:
        return
    fine = min(probes.reference_spacings)
    inc = probes.inclusions[0]
    planes = layered_reference.layer_planes(ABDOMINAL_WALL_THICKNESS)
    centre = (*inc.position, layered_reference.nodule_centre_z(planes, "fat", inc.radius))
    vol = layered_reference.wall_volume(tuple(LayeredPalpationConfig().size), planes, inc.position, fine, centre,
                                        inc.radius)
    layered_reference.require_site_memory(task, vol, fine, "over")


def reference_row(task: str, probes: ProbeSet, fine: float, sites: tuple[str, ...] = ("over", "mirror")) -> dict:
    """The reference of ``probes`` at fine spacing ``fine`` (m): :func:`layered_reference.reference_row`
    on the task's wall (its patch size, layers, materials, nodule and probe); ``sites``: the press sites
    to solve ("over", "mirror"; one per process keeps a fine level's memory and time per run down)."""
    from surgsim_envs.bench import layered_reference
    from surgsim_envs.envs.layered_palpation import LayeredPalpationConfig
    from surgsim_envs.geometry.anatomy import ABDOMINAL_WALL_THICKNESS, ANATOMY_MATERIALS
    from surgsim_envs.materials import PRESETS

    cfg = LayeredPalpationConfig()
    if len(probes.inclusions) != 1:
        raise ConfigError(f"{TASK}: the task hides one nodule; the probe set has {len(probes.inclusions)}")
    inc = probes.inclusions[0]
    every = {"over": tuple(inc.position), "mirror": mirror(inc.position)}
    unknown = sorted(set(sites) - set(every))
    if unknown or not sites:
        raise ConfigError(f"{TASK}: reference sites {list(sites)!r}: choose from {list(every)}")
    sites = {name: every[name] for name in sites}
    return layered_reference.reference_row(
        task, sites, probes.depths, fine, size=tuple(cfg.size), thickness=ABDOMINAL_WALL_THICKNESS,
        materials={**PRESETS, **ANATOMY_MATERIALS}, nodule_xy=inc.position, nodule_radius=inc.radius,
        nodule_factor=inc.contrast, nodule_layer="fat", tip_radius=cfg.probe_radius)


__all__ = ["TASK", "MODELS", "REFERENCE_DESCRIPTION", "NODULE", "FULL", "QUICK", "OFF_NODE", "Presser", "measure",
           "reference_key",
           "check_reference_memory", "reference_row"]
