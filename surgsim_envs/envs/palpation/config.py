"""Palpation-v0's settings: :class:`PalpationConfig` (SI units) and its checks."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from surgsim_envs import validate
from surgsim_envs.envs.checks import (check_contact_law, check_contact_stiffness_per_area, check_control_rate, check_integrator,
                                     check_on_unstable, check_positive,
                                     check_range, check_render_size, check_task_length, check_task_resolution,
                                     check_weights)
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
    spacing: float = 0.005             # m, tissue lattice spacing (2,205 nodes for the default slab)
    resolution: float | str | None = None   # None: ``spacing``; a spacing in m; "auto": from the accuracy table
    error_tolerance: float = 0.1       # resolution="auto": force error limit (fraction)
    step_budget_us: float = 5_000.0    # resolution="auto": compute limit, us per simulated ms
    on_unstable: str = "raise"         # "terminate": a tissue divergence ends the episode (info["unstable"])
    slab_size: Sequence[float] = (0.1, 0.1, 0.02)   # m
    material: str = "liver"
    # a registered tissue model with the capabilities PalpationEnv.REQUIRES; the default (with ``spacing``) is
    # the cheapest setting within the task's 10 % force tolerance in docs/task_accuracy.md
    model: str = "fem_static"
    integrator: str = "symplectic"     # if the model has it and it is stable over the stiffness ranges, else "auto"
    tip_radius: float = 0.01           # m, probe tip
    # N/m^3, probe-tissue contact stiffness per unit surface area: "auto" = 1e8 for quasi-static tissue
    # models (their equilibrium solve takes it at any spacing), the scene's 200 N/m per node for the
    # others (what an explicit step keeps stable); None = always per node (ContactConfig.stiffness_per_area)
    contact_stiffness_per_area: Any = "auto"
    # how a quasi-static model's step takes the probe's contact (ContactConfig.law): "linearised" (one
    # isotropic stiffness per node), "plane" (penalty and Coulomb friction solved with the step) or "auto"
    contact_law: str = "auto"
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
        for key in ("tip_radius", "max_depth"):
            check_task_length(getattr(self, key), f"PalpationConfig.{key}")
        for key in ("hover", "max_xy_step", "xy_limit", "press_min_depth", "site_spacing", "localisation_scale",
                    "map_half_width"):     # positive above; bounded here (1e308 m overflows the geometry)
            check_task_length(getattr(self, key), f"PalpationConfig.{key}", lo=0.0)
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
        check_contact_stiffness_per_area(self.contact_stiffness_per_area, "PalpationConfig.contact_stiffness_per_area")
        check_contact_law(self.contact_law, "PalpationConfig.contact_law")
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
    if not validate.has_length(value, 3):
        raise ConfigError(f"{what}={value!r} must be three positive lengths in m, e.g. (0.1, 0.1, 0.02)")
    return np.array([validate.positive(v, f"{what}[{i}]", hi=1.0, unit="m", fix="slab sides are lengths in (0, 1] m")
                     for i, v in enumerate(value)])

