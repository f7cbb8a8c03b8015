"""SurgSim/Palpation-v0: find a hidden stiff inclusion in a tissue slab with a probe.

A liver slab (default 10 x 10 x 2 cm, bed fixed, mass-spring, 10 mm lattice: 363 nodes; or
``resolution`` = a spacing in m / "auto", see :class:`PalpationConfig`) hides a
spherical inclusion of random position, radius and stiffness contrast. The agent moves a
spherical-tip probe and presses; every control step with the tip deeper than ``press_min_depth``
while the tip moves slower than ``sample_max_speed`` (a quasi-static press: a moving tip's force
includes damping and drag) is a stiffness sample (x, y, F_z / depth). The env keeps a running stiffness-weighted estimate of
the inclusion centre from these samples (:func:`stiffness_weighted_estimate`); when the agent is
sure it raises the "report" action and that estimate is its guess (at the time limit too). The
agent's job is to press at informative sites and to report once the estimate is good.

Action (4,) in [-1, 1]: ``[vx, vy, press, report]``; vx, vy move the probe target by up to
``max_xy_step`` m per control step; press sets the target depth from ``hover`` m above the rest
surface (-1) to ``max_depth`` m below it (+1); report > 0 held for ``report_hold_steps``
consecutive control steps ends the episode with the guess (ignored during the first
``min_report_seconds``; the hold makes reporting a deliberate act rather than a one-step
coin flip of a stochastic policy).

Observation (14,) float32, SI: probe tip-centre position (3) m; contact force on the probe (3)
N; indentation depth (1) m below the rest surface; best stiffness site so far (x, y) (2) m and
its stiffness estimate F_z / depth (1) N/m; elapsed fraction of the episode (1); the running
estimate of the inclusion centre (x, y) (2) m (the probe's (x, y) before the first sample);
stiffness contrast seen so far, max / median sampled stiffness (1) (1 before any sample); then a
coarse stiffness map (``map_cells`` x ``map_cells``, row-major, y rows then x columns) over the square
+-``map_half_width`` m: per cell the largest stiffness sample taken in it divided by the largest
sample so far (dimensionless, in (0, 1]; 0 if the cell was never sampled), so the agent sees which
cells it has covered and where the tissue is stiff (:func:`stiffness_map`). Default (39,).

Reward: ``press_reward`` for each press deeper than ``press_min_depth`` at a site at least
``site_spacing`` m from earlier ones and ``cell_reward`` for the first stiffness sample in each
map cell (coverage; both are bounded per episode); potential-based shaping ``shaping_weight *
(phi_t - phi_{t-1})`` with ``phi = 1 - min(err_estimate / localisation_scale, 1)`` (0 before the
first sample): presses that move the estimate toward the inclusion pay at once, and the sum over
an episode is just ``shaping_weight * phi_final``, so it cannot be farmed; ``- time_cost`` per
step; ``- damage_weight * (|F| - damage_force)`` per step above the tissue-damage force; at the
end ``localisation_weight * (1 - min(err / localisation_scale, 1)) + success_bonus * success``.
``info["success"]``: guess within ``tolerance_mm``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from gymnasium import spaces

from surgsim_envs import validate
from surgsim_envs.envs.base import (SurgSimEnv, check_control_rate, check_explicit_step, check_integrator,
                                   check_on_unstable, check_positive, check_range, check_render_size,
                                   check_task_resolution, check_weights, ObsTerm, require_capabilities,
                                   integrator_for_range, reward_from_terms, sample, sphere_mask, tissue_options)
from surgsim_envs.errors import ConfigError
from surgsim_envs.materials import get_material


#: m; with the slab at least this much thicker than ``max_depth`` the probe cannot reach the floor and the
#: scene runs without MuJoCo's collision detection (``SceneConfig.rigid_contacts``)
RIGID_CONTACT_CLEARANCE = 0.005


@dataclass
class PalpationConfig:
    """Palpation-v0 settings (SI units). Ranges are (low, high) sampled uniformly per episode."""

    # physics / timing
    control_hz: float = 100.0          # Hz, control rate
    dt: float = 1e-3                   # s, physics step (substeps = round(1 / (control_hz dt)))
    episode_seconds: float = 6.0       # s, time limit
    spacing: float = 0.01              # m, tissue lattice spacing (363 nodes for the default slab)
    resolution: float | str | None = None   # None: ``spacing``; a spacing in m; "auto": from the accuracy table
    error_tolerance: float = 0.1       # resolution="auto": force error limit (fraction)
    step_budget_us: float = 5_000.0    # resolution="auto": compute limit, us per simulated ms
    on_unstable: str = "raise"         # "terminate": a tissue divergence ends the episode (info["unstable"])
    slab_size: Sequence[float] = (0.1, 0.1, 0.02)   # m
    material: str = "liver"
    model: str = "mass_spring"         # any registered tissue model with the "forces" capability
    integrator: str = "symplectic"     # if the model has it and it is stable over the stiffness ranges, else "auto"
    tip_radius: float = 0.01           # m, probe tip
    probe_speed: float = 0.2           # m/s, rate limit of the probe target
    # action scaling
    max_xy_step: float = 0.003         # m per control step
    hover: float = 0.002               # m above the rest surface at press = -1
    max_depth: float = 0.008           # m below the rest surface at press = +1
    xy_limit: float = 0.045            # m, probe target |x|, |y| bound
    # randomisation (per episode)
    inclusion_xy: Sequence[float] = (-0.03, 0.03)     # m, centre x and y range
    inclusion_depth: Sequence[float] = (0.008, 0.011)  # m, centre below the top surface
    inclusion_radius: Sequence[float] = (0.007, 0.011)  # m
    stiffness_contrast: Sequence[float] = (3.0, 5.0)   # E_inclusion / E_tissue
    young_scale: Sequence[float] = (0.8, 1.1)         # scales the whole slab's Young's modulus
    # reward
    press_min_depth: float = 0.003     # m, a press counts from this depth
    sample_max_speed: float = 0.05     # m/s, stiffness samples only from quasi-static presses (tip slower)
    site_spacing: float = 0.01         # m, new press sites must be this far from earlier ones
    press_reward: float = 0.05
    max_rewarded_sites: int = 25
    cell_reward: float = 0.04          # first stiffness sample in each map cell (coverage; <= cells^2 x this)
    # observation: coarse stiffness map
    map_cells: int = 5                 # map_cells x map_cells grid
    map_half_width: float = 0.0375     # m, the map covers |x|, |y| <= this (5 cells of 15 mm around +-3 cm)
    damage_force: float = 1.5          # N, tissue-damage threshold
    damage_weight: float = 1.0         # per N above the threshold per step
    localisation_weight: float = 1.0
    localisation_scale: float = 0.04   # m
    success_bonus: float = 1.0
    shaping_weight: float = 1.0        # potential-based shaping on the running estimate's error
    time_cost: float = 0.0005          # per control step (0.3 over a full 6 s episode)
    tolerance_mm: float = 10.0         # mm
    min_report_seconds: float = 1.0    # s, "report" is ignored before this (stops reflexive guesses)
    report_hold_steps: int = 5         # report > 0 must be held this many consecutive control steps
    # rendering
    camera: str = "overview"
    render_width: int = 480
    render_height: int = 480

    def validate(self) -> None:
        for key in ("control_hz", "dt", "episode_seconds", "spacing", "tip_radius", "probe_speed", "max_xy_step",
                    "hover", "max_depth", "xy_limit", "press_min_depth", "sample_max_speed", "site_spacing", "damage_force",
                    "localisation_scale", "tolerance_mm", "map_half_width"):
            check_positive(getattr(self, key), f"PalpationConfig.{key}")
        check_control_rate(self, "PalpationConfig")
        check_weights(self, ("shaping_weight", "time_cost", "press_reward", "cell_reward", "damage_weight",
                             "localisation_weight", "success_bonus"), "PalpationConfig")
        check_integrator(self, "PalpationConfig")
        try:
            get_material(self.material)
        except (ConfigError, TypeError, ValueError) as exc:
            raise ConfigError(f"PalpationConfig.material={validate.short_repr(self.material)}: {exc}") from None
        check_render_size(self, "PalpationConfig")
        validate.integer(self.max_rewarded_sites, "PalpationConfig.max_rewarded_sites", lo=0, hi=10_000,
                         fix="a count of press sites, e.g. 25")
        check_task_resolution(self, "PalpationConfig")
        check_on_unstable(self.on_unstable, "PalpationConfig")
        if not (isinstance(self.map_cells, (int, np.integer)) and 1 <= self.map_cells <= 20):
            raise ConfigError(f"PalpationConfig.map_cells={self.map_cells!r} must be an integer in [1, 20]")
        validate.integer(self.report_hold_steps, "PalpationConfig.report_hold_steps", lo=1,
                         hi=int(round(self.episode_seconds * self.control_hz)),
                         fix="a count of control steps no longer than the episode, e.g. 5")
        if 1.0 / self.control_hz < self.dt:
            raise ConfigError(f"control period 1/control_hz={1 / self.control_hz:g} s is shorter than dt={self.dt:g} s; "
                              "lower control_hz or dt")
        validate.real(self.min_report_seconds, "PalpationConfig.min_report_seconds", lo=0.0, hi=self.episode_seconds,
                      unit="s", fix="it must lie in [0, episode_seconds]")
        size = check_slab_size(self.slab_size, "PalpationConfig.slab_size")
        validate.grid_nodes(size, self.resolution if validate.is_real_number(self.resolution) else self.spacing,
                            "PalpationConfig", hi=MAX_TASK_NODES,
                            fix="use a coarser spacing or resolution (an episode would take hours)")
        if self.xy_limit > size[:2].min() / 2:
            raise ConfigError(f"xy_limit={self.xy_limit} m exceeds half the slab ({size[:2].min() / 2} m)")
        half = size[:2].min() / 2
        check_range(self.inclusion_xy, "inclusion_xy", -half, half)
        check_range(self.inclusion_depth, "inclusion_depth", 0.0, float(size[2]))
        check_range(self.inclusion_radius, "inclusion_radius", 1e-4, float(size.max()))
        check_range(self.stiffness_contrast, "stiffness_contrast", 1.0, 20.0)
        check_range(self.young_scale, "young_scale", 0.1, 10.0)


#: nodes of a task's tissue lattice: a mass-spring step of 10^6 nodes takes seconds, so an
#: episode of a few hundred control steps takes hours; a finer lattice is a typo, not a task
MAX_TASK_NODES = 1_000_000


def check_slab_size(value, what: str) -> np.ndarray:
    """(3,) float array of a slab's positive finite side lengths in m (each at most 1 m)."""
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 3:
        raise ConfigError(f"{what}={value!r} must be three positive lengths in m, e.g. (0.1, 0.1, 0.02)")
    return np.array([validate.positive(v, f"{what}[{i}]", hi=1.0, unit="m", fix="slab sides are lengths in (0, 1] m")
                     for i, v in enumerate(value)])


# ----------------------------------------------------------------------------------------------
# term functions (each testable alone)
def indentation_depth(probe_z: float, surface_z: float, tip_radius: float) -> float:
    """m the probe tip's lowest point lies below the rest surface (0 above it)."""
    return max(0.0, surface_z + tip_radius - probe_z)


def stiffness_estimate(force_z: float, depth: float, min_depth: float) -> float:
    """Apparent stiffness F_z / depth (N/m) of a press deeper than ``min_depth`` m, else 0; always a
    Python float (the same IEEE quotient as with numpy scalars: one type in every step's info keeps
    the vector env's info write plan, ``envs/vector_info.py``, from being rebuilt)."""
    return float(force_z) / float(depth) if depth >= min_depth else 0.0


def is_new_site(xy: np.ndarray, sites: list, spacing: float) -> bool:
    """True if ``xy`` (2,) m is at least ``spacing`` m from every earlier press site."""
    return all(float(np.hypot(*(xy - s))) >= spacing for s in sites)


def _norm(v) -> float:
    """Euclidean norm of a small vector: ``np.linalg.norm``'s own formula, sqrt(v . v), without its
    wrapper (same result bit for bit)."""
    v = np.asarray(v, dtype=float).ravel()
    return math.sqrt(v.dot(v))


def damage_penalty(force: np.ndarray, threshold: float, weight: float) -> float:
    """-weight * (|force| - threshold) above the tissue-damage threshold (N), else 0."""
    return -weight * max(0.0, _norm(force) - threshold)


def stiffness_weighted_estimate(xy: np.ndarray, k: np.ndarray, power: float = 3.0) -> np.ndarray:
    """(2,) m: centroid of sample positions ``xy`` (n, 2) m weighted by ``(k - median(k))+ ** power``
    (k: (n,) N/m stiffness samples); the stiffest sample's position if no sample is above the median."""
    xy, k = np.asarray(xy, dtype=float).reshape(-1, 2), np.asarray(k, dtype=float).reshape(-1)
    if len(k) == 0 or len(k) != len(xy):
        raise ConfigError(f"stiffness_weighted_estimate needs n >= 1 samples with matching xy (n, 2) and k (n,), "
                          f"got xy {xy.shape} and k {k.shape}")
    return _weighted_estimate(xy, k, np.median(k), power)


def _weighted_estimate(xy: np.ndarray, k: np.ndarray, median, power: float = 3.0) -> np.ndarray:
    """:func:`stiffness_weighted_estimate` of checked (n, 2) / (n,) float arrays with ``median`` =
    ``np.median(k)`` given (the env computes it once per sample for the estimate and the contrast)."""
    w = np.clip(k - median, 0.0, None) ** power
    total = float(w.sum())
    if total <= 0.0:
        return xy[int(np.argmax(k))].copy()
    return (w[:, None] * xy).sum(axis=0) / total


def map_cell(xy: np.ndarray, cells: int, half_width: float) -> int:
    """Row-major index (row = y, column = x) of the ``cells`` x ``cells`` map cell over the square
    +-``half_width`` m that contains ``xy`` (2,) m; points outside fall into the nearest edge cell."""
    if not (isinstance(cells, (int, np.integer)) and cells >= 1) or not half_width > 0:
        raise ConfigError(f"map_cell needs cells >= 1 and half_width > 0 m, got {cells!r}, {half_width!r}")
    xy = np.asarray(xy, dtype=float).reshape(-1)
    if xy.shape != (2,) or not np.all(np.isfinite(xy)):
        raise ConfigError(f"map_cell needs a finite (x, y) in m, got {xy!r}")
    return _cell_of(float(xy[0]), float(xy[1]), int(cells), float(half_width))


def _cell_of(x: float, y: float, cells: int, half_width: float) -> int:
    """:func:`map_cell` of checked finite floats (the same arithmetic, in Python floats)."""
    i = min(max(math.floor((x + half_width) / (2 * half_width) * cells), 0), cells - 1)
    j = min(max(math.floor((y + half_width) / (2 * half_width) * cells), 0), cells - 1)
    return int(j * cells + i)


def stiffness_map(cell_max_k: np.ndarray) -> np.ndarray:
    """Dimensionless map: per-cell max stiffness sample ``cell_max_k`` (N/m, 0 = never sampled)
    divided by the largest one (all zeros before any sample)."""
    k = np.asarray(cell_max_k, dtype=float)
    if np.any(~np.isfinite(k)) or np.any(k < 0):
        raise ConfigError("stiffness_map needs finite per-cell stiffness values >= 0 N/m")
    top = float(k.max()) if k.size else 0.0
    return k / top if top > 0 else np.zeros_like(k)


def _normalised(k: np.ndarray) -> np.ndarray:
    """:func:`stiffness_map` of the env's own per-cell array (finite, >= 0 by construction): no checks."""
    top = k.max() if k.size else 0.0
    return k / top if top > 0 else np.zeros_like(k)


def column_contrast(points: np.ndarray, centre, radius: float, contrast: float, bottom: float) -> np.ndarray:
    """(P,) stiffness factor of the vertical tissue column from height ``bottom`` (m) up to each point of
    ``points`` (P, 3) m, with a sphere (``centre`` (3,) m, ``radius`` m) ``contrast`` times stiffer than
    the rest: the series (Reuss) average over the column, ``h / ((h - l) + l / contrast)`` with h the
    column's height and l the length of it inside the sphere (1 where h = 0 or the column misses it)."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    c = np.asarray(centre, dtype=float)
    half = np.sqrt(np.clip(radius ** 2 - ((p[:, :2] - c[:2]) ** 2).sum(axis=1), 0.0, None))
    top = p[:, 2]
    inside = np.clip(np.minimum(c[2] + half, top) - np.maximum(c[2] - half, bottom), 0.0, None)
    h = top - bottom
    out = np.ones(len(p))
    ok = h > 0
    out[ok] = h[ok] / ((h[ok] - inside[ok]) + inside[ok] / contrast)
    return out


def localisation_error(guess_xy: np.ndarray, true_xy: np.ndarray) -> float:
    """m, planar distance from the guess to the inclusion centre."""
    return float(np.hypot(*(np.asarray(guess_xy, dtype=float) - np.asarray(true_xy, dtype=float))))


def localisation_reward(error: float, scale: float, tolerance: float, weight: float, bonus: float) -> float:
    """weight * (1 - min(error / scale, 1)) + bonus if error <= tolerance (all in m)."""
    return weight * (1.0 - min(error / scale, 1.0)) + (bonus if error <= tolerance else 0.0)


# ----------------------------------------------------------------------------------------------
class PalpationEnv(SurgSimEnv):
    """Palpation-v0 (see module docstring)."""

    config_cls = PalpationConfig
    TASK_ID = "SurgSim/Palpation-v0"
    REQUIRES = ("forces",)      # tissue capabilities the task needs (contract v2)
    OPTIONS = ("inclusion_position", "inclusion_xy", "inclusion_depth", "inclusion_radius", "stiffness_contrast", "young_scale")

    def _build(self) -> None:
        from surgsim_envs.scene import Simulation, palpation_config, palpation_scene
        from surgsim_envs.tissue.registry import get as model_class

        c = self.config
        cfg = palpation_config(organ="slab")
        t = cfg.tissues[0]
        t.spacing = c.spacing
        t.resolution, t.error_tolerance, t.step_budget_us = c.resolution, c.error_tolerance, c.step_budget_us
        t.material = c.material
        t.model = c.model
        # the probe tip (10 mm) presses about one lattice spacing of surface: a concentrated load, so the
        # model is built with the options it declares for one (``TissueModel.point_load_options``; a model
        # from outside the package may not declare any)
        t.options = {**tissue_options(c.model, c.integrator),
                     **getattr(model_class(c.model), "point_load_options", {})}
        t.region_materials = None
        t.volume_options = {"size": tuple(float(s) for s in c.slab_size)}
        t.position = (0.0, 0.0, float(c.slab_size[2]) / 2.0)
        self.surface_z = float(c.slab_size[2])
        p = cfg.tool("probe")
        p.tip_radius = c.tip_radius
        p.position = (0.0, 0.0, self.surface_z + c.tip_radius + c.hover)
        cfg.dt = c.dt
        # the probe's deepest commanded tip stays this far above the floor: MuJoCo's collision detection
        # (probe vs floor, the only rigid pair) has nothing to find and is switched off
        cfg.rigid_contacts = self.surface_z - c.max_depth < RIGID_CONTACT_CLEARANCE
        require_capabilities(c.model, self.REQUIRES, self.TASK_ID)
        self.sim = Simulation(palpation_scene(cfg), dt=c.dt, substeps=self.substeps)
        stiffest = check_range(c.young_scale, "young_scale")[1] * check_range(c.stiffness_contrast, "contrast")[1]
        switch = integrator_for_range(self.sim.tissue(), c.dt, stiffest)   # inclusion: young_scale x contrast
        if switch is not None:
            t.options = {**t.options, "integrator": switch}
            self.sim = Simulation(palpation_scene(cfg), dt=c.dt, substeps=self.substeps)
        self.centroids = self.sim.tissue().element_centroids()     # (T,3) m, rest frame: inclusion masks
        self.home = np.asarray(p.position, dtype=float)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32)
        self.n_cells = int(c.map_cells) ** 2
        reach = float(p.travel)                          # the probe's slides: home +- travel per axis
        lo, hi = float(self.home[:2].min()) - reach, float(self.home[:2].max()) + reach
        self._set_observation_terms([
            ObsTerm("probe_tip_position", "m", 3, float(self.home.min()) - reach, float(self.home.max()) + reach),
            ObsTerm("contact_force", "N", 3),
            ObsTerm("indentation_depth", "m", 1, 0.0),
            ObsTerm("best_site_xy", "m", 2, lo, hi),
            ObsTerm("best_stiffness", "N/m", 1, 0.0),
            ObsTerm("episode_fraction", "1", 1, 0.0, 1.0),
            ObsTerm("estimate_xy", "m", 2, lo, hi),
            ObsTerm("stiffness_contrast_seen", "1", 1, 1.0),
            ObsTerm("stiffness_map", "1", self.n_cells, 0.0, 1.0)])
        self.inclusion = {}
        self._centre_list = None                 # (inclusion centre array, its list) for the infos
        self._map_obs = self._cells_sampled = None

    # -- episode ----------------------------------------------------------------------------
    def _randomise(self, options: dict[str, Any]) -> None:
        c, rng = self.config, self.np_random
        get = lambda k: options.get(k, getattr(c, k))  # noqa: E731
        half = float(min(c.slab_size[:2])) / 2
        xy = get("inclusion_xy")
        x = sample(rng, xy, "inclusion_xy", -half, half)
        y = sample(rng, xy, "inclusion_xy", -half, half)
        if options.get("inclusion_position") is not None:
            value = options["inclusion_position"]
            if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
                raise ConfigError(f"inclusion_position must be (x, y) m inside +-{half} m, "
                                  f"got {validate.short_repr(value)}")
            x, y = (validate.real(v, f"inclusion_position[{i}]", lo=-half, hi=half, unit="m",
                                  fix=f"the inclusion centre lies inside the slab, +-{half} m")
                    for i, v in enumerate(value))
        depth = sample(rng, get("inclusion_depth"), "inclusion_depth", 0.0, float(c.slab_size[2]))
        radius = sample(rng, get("inclusion_radius"), "inclusion_radius", 1e-4, float(max(c.slab_size)))
        contrast = sample(rng, get("stiffness_contrast"), "stiffness_contrast", 1.0, 20.0)
        scale = sample(rng, get("young_scale"), "young_scale", 0.1, 10.0)
        centre = np.array([x, y, self.surface_z - depth])
        tissue = self.sim.tissue()
        if "surface_only" in getattr(tissue, "capabilities", ()):
            # a surface-only model's elements are its surface nodes, each standing for the column of tissue
            # under it: the inclusion reaches it as that column's series stiffness (the sphere lies below)
            tissue.scale_material("young", scale * column_contrast(self.centroids, centre, radius, contrast, 0.0))
        else:
            tissue.scale_material("young", scale)             # the contract's only way to change stiffness
            tissue.scale_material("young", scale * contrast, mask=sphere_mask(self.centroids, centre, radius))
        self.sim.reset(seed=int(rng.integers(2**31)))
        check_explicit_step(tissue, self.sim.dt, f"Palpation: stiffness contrast {contrast:.2f} x young_scale "
                                                 f"{scale:.2f}")
        self.inclusion = {"centre": centre, "radius": radius, "contrast": contrast, "young_scale": scale}
        self.target = self.home.copy()
        self.sim.set_tool_target("probe", self.target, speed=c.probe_speed)
        self.sites: list[np.ndarray] = []
        self.best = (0.0, 0.0, 0.0)  # x, y, stiffness estimate
        self.samples_xy: list[np.ndarray] = []   # m, positions of the stiffness samples
        self.samples_k: list[float] = []         # N/m
        self.estimate = None                     # (2,) m, running stiffness-weighted estimate
        self.contrast_seen = 1.0                 # max / median sampled stiffness
        self.cell_k = np.zeros(self.n_cells)     # N/m, max stiffness sample per map cell (0 = none)
        self._map_obs = None                     # the map's observation entries (from cell_k), cached
        self._cells_sampled = None               # map cells with a sample (from cell_k), cached
        self.phi = 0.0                           # shaping potential of the running estimate
        self.prev_tip = self.sim.tool_position("probe").copy()
        self.report_held = 0                     # consecutive control steps with report > 0
        self.guess = None
        self.error = None

    def _apply_action(self, a: np.ndarray) -> None:
        c = self.config
        a0, a1, a2 = a.tolist()[:3]
        tx, ty = self.target.tolist()[:2]
        lim, step = c.xy_limit, c.max_xy_step
        x = tx + a0 * step                        # = np.clip(target[:2] + a[:2] * step, -lim, lim), in floats
        y = ty + a1 * step
        x = lim if x > lim else (-lim if x < -lim else x)
        y = lim if y > lim else (-lim if y < -lim else y)
        press = (a2 + 1.0) / 2.0
        z = self.surface_z + c.tip_radius + c.hover - press * (c.hover + c.max_depth)
        self.target = np.array([x, y, z])
        self.sim.set_tool_target("probe", self.target, speed=c.probe_speed)
        self.sim.step()

    def _readings(self):
        """(probe position (3,) m, force on the probe (3,) N, indentation depth m), read once per
        physics state (``_evaluate`` and ``_observe`` of a step share them; do not modify them)."""
        sim = self.sim
        key = (sim, sim.steps, self.steps)         # reset() and the unstable path clear the key
        if self._readings_key != key:
            pos = sim.tool_position("probe")
            force = sim.tool_force("probe")
            self._readings_value = (pos, force, indentation_depth(pos[2], self.surface_z, self.config.tip_radius))
            self._readings_key = key
        return self._readings_value

    def _observe(self) -> np.ndarray:
        pos, force, depth = self._readings()
        frac = self.steps / self.max_episode_steps
        est = self.estimate if self.estimate is not None else pos[:2]
        obs = np.empty(14 + self.n_cells, dtype=np.float32)
        obs[0:3] = pos
        obs[3:6] = force
        obs[6:14] = (depth, self.best[0], self.best[1], self.best[2], frac, est[0], est[1], self.contrast_seen)
        if self._map_obs is None:              # the map changes only when a sample is recorded
            self._map_obs = _normalised(self.cell_k)
        obs[14:] = self._map_obs
        return obs

    def _evaluate(self, a: np.ndarray):
        c = self.config
        pos, force, depth = self._readings()
        fmag = math.sqrt(force.dot(force))        # = _norm(force)
        if fmag > self.peak_force:
            self.peak_force = fmag
        # = damage_penalty(force, ...), on the norm computed once
        rt = {"damage": -c.damage_weight * max(0.0, fmag - c.damage_force), "coverage": 0.0, "shaping": 0.0,
              "time": -c.time_cost, "press_site": 0.0, "localisation": 0.0}
        k = stiffness_estimate(force[2], depth, c.press_min_depth)
        if k > self.best[2]:
            self.best = (float(pos[0]), float(pos[1]), k)
        d = pos - self.prev_tip
        speed = math.sqrt(d.dot(d)) / self.control_dt   # = _norm(d)
        self.prev_tip = pos.copy()
        if k > 0.0 and speed <= c.sample_max_speed:
            self._record_sample(pos[:2].copy(), k, rt)
        # a press site counts only when it gives a quasi-static stiffness sample (dragging a pressed tip
        # across the slab measures drag, not stiffness, and must not pay)
        if (depth >= c.press_min_depth and speed <= c.sample_max_speed
                and is_new_site(pos[:2], self.sites, c.site_spacing)):
            self.sites.append(pos[:2].copy())
            if len(self.sites) <= c.max_rewarded_sites:
                rt["press_site"] += c.press_reward
        terms: dict[str, Any] = {"stiffness_estimate_N_per_m": k, "force_N": fmag,
                                 "estimate_xy_m": None if self.estimate is None else self.estimate.tolist()}
        self.report_held = self.report_held + 1 if a[3] > 0.0 else 0
        terminated = (self.report_held >= c.report_hold_steps
                      and self.steps * self.control_dt >= c.min_report_seconds)
        if terminated:
            r, t = self._finish(pos)
            rt["localisation"] += r
            terms.update(t)
        reward, terms["reward_terms"] = reward_from_terms(rt)
        return reward, terminated, terms

    def _record_sample(self, xy: np.ndarray, k: float, rt: dict[str, float]) -> None:
        """Add a quasi-static stiffness sample ``k`` (N/m) at ``xy`` (m): the map cell (coverage
        reward if new), the stiffness-weighted estimate, the contrast seen, and the potential-based
        shaping on the estimate's error (reward terms accumulate in ``rt``)."""
        c = self.config
        if not self.samples_k or getattr(self, "_sample_buf", None) is None:
            self._sample_buf = [np.empty((64, 2)), np.empty(64), -np.inf]   # a new episode's samples
        self.samples_xy.append(xy)
        self.samples_k.append(k)
        # the samples also go into growing arrays, so the estimate does not rebuild them from the lists
        n = len(self.samples_k)
        buf = self._sample_buf
        if n > len(buf[1]):
            buf[0] = np.concatenate([buf[0], np.empty_like(buf[0])])
            buf[1] = np.concatenate([buf[1], np.empty_like(buf[1])])
        buf[0][n - 1] = xy
        buf[1][n - 1] = k
        buf[2] = max(buf[2], float(k))
        cell = _cell_of(float(xy[0]), float(xy[1]), int(c.map_cells), float(c.map_half_width))
        if self.cell_k[cell] == 0.0:
            rt["coverage"] += c.cell_reward
        self.cell_k[cell] = max(self.cell_k[cell], k)
        self._map_obs = self._cells_sampled = None
        median = np.median(buf[1][:n])           # once for the estimate and the contrast
        self.estimate = _weighted_estimate(buf[0][:n], buf[1][:n], median)
        med = float(median)
        self.contrast_seen = buf[2] / med if med > 0 else 1.0
        err = localisation_error(self.estimate, self.inclusion["centre"][:2])
        phi = 1.0 - min(err / c.localisation_scale, 1.0)
        rt["shaping"] += c.shaping_weight * (phi - self.phi)
        self.phi = phi

    def _finish(self, pos) -> tuple[float, dict[str, Any]]:
        c = self.config
        self.guess = (self.estimate if self.estimate is not None else pos[:2]).copy()
        self.error = localisation_error(self.guess, self.inclusion["centre"][:2])
        r = localisation_reward(self.error, c.localisation_scale, c.tolerance_mm * 1e-3, c.localisation_weight,
                                c.success_bonus)
        return r, {"guess_xy_m": self.guess.tolist(), "localisation_error_m": self.error}

    def _on_truncate(self):
        pos = self.sim.tool_position("probe")
        return self._finish(pos)

    def _metrics(self) -> dict[str, Any]:
        inc = self.inclusion
        success = self.error is not None and self.error <= self.config.tolerance_mm * 1e-3
        if self._cells_sampled is None:          # the map changed: count again
            self._cells_sampled = int(np.count_nonzero(self.cell_k))
        centre = self._centre_list
        if centre is None or centre[0] is not inc["centre"]:
            centre = self._centre_list = (inc["centre"], inc["centre"].tolist())
        return {"inclusion_centre_m": list(centre[1]), "inclusion_radius_m": inc["radius"],
                "stiffness_contrast": inc["contrast"], "press_sites": len(self.sites),
                "map_cells_sampled": self._cells_sampled, "success": bool(success), "is_success": bool(success)}


def palpation_expert(env, grid: int = 5, depth_action: float = 0.6) -> Any:
    """A scripted policy: press ``depth_action`` (6 mm deep) for 12 control steps at each site of a
    ``grid`` x ``grid`` raster over the inclusion's range, then report (the env's stiffness-weighted
    estimate of the samples is the guess). Returns a callable ``policy(obs) -> action``."""
    c = env.unwrapped.config
    lim = float(min(c.inclusion_xy[1], c.xy_limit))
    xs = np.linspace(-lim, lim, grid)
    pts = [np.array([x, y]) for j, y in enumerate(np.linspace(-lim, lim, grid)) for x in (xs if j % 2 == 0 else xs[::-1])]
    state = {"i": 0, "phase": "move", "n": 0}

    def policy(obs):
        if state["i"] == len(pts):
            return np.array([0, 0, -1, 1], dtype=np.float32)
        d = pts[state["i"]] - obs[:2]
        if state["phase"] == "move":
            if np.hypot(*d) < 0.0015:
                state["phase"], state["n"] = "press", 0
            return np.array([*np.clip(d / c.max_xy_step, -1, 1), -1, -1], dtype=np.float32)
        state["n"] += 1
        if state["n"] >= 12:
            state["i"] += 1
            state["phase"] = "move"
            return np.array([0, 0, -1, -1], dtype=np.float32)
        return np.array([*np.clip(d / c.max_xy_step, -1, 1), depth_action, -1], dtype=np.float32)

    return policy
