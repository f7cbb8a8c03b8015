"""SurgSim/Palpation-v0: find a hidden stiff inclusion in a tissue slab with a probe.

A liver slab (default 10 x 10 x 2 cm, bed fixed, quasi-static FEM ``fem_static`` on a 5 mm lattice:
2,205 nodes, the cheapest setting within the task's 10 % force tolerance, docs/task_accuracy.md; or
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

from typing import Any

import numpy as np
from gymnasium import spaces

from surgsim_envs import validate
from surgsim_envs.envs.base import SurgSimEnv
from surgsim_envs.envs.checks import check_explicit_step, check_range, require_capabilities, sample
from surgsim_envs.envs.palpation.config import RIGID_CONTACT_CLEARANCE, PalpationConfig
from surgsim_envs.envs.palpation.terms import (REWARD_TERMS, TERMINATION_TERMS, cell_of,
                                              indentation_depth, is_new_site, localisation_error,
                                              localisation_potential, localisation_reward, normalised_map,
                                              stiffness_estimate, weighted_estimate)
from surgsim_envs.envs.terms import ObsTerm
from surgsim_envs.envs.terms.action import ActionTerm, probe_target
from surgsim_envs.envs.terms.force import vector_norm
from surgsim_envs.envs.tissue_setup import inclusion_young_factors, integrator_for_range, tissue_options
from surgsim_envs.errors import ConfigError


# ----------------------------------------------------------------------------------------------
class PalpationEnv(SurgSimEnv):
    """Palpation-v0 (see module docstring)."""

    config_cls = PalpationConfig
    TASK_ID = "SurgSim/Palpation-v0"
    #: tissue capabilities the task needs (contract v2): a probe must feel an inclusion below the surface,
    #: so a surface-only model (whose interior carries nothing) is refused by name
    REQUIRES = ("forces", "subsurface_stiffness")
    ACTION = ActionTerm("probe", 4, "[vx, vy, press, report]: target step (x, y), depth, report")
    REWARD_TERMS = REWARD_TERMS
    TERMINATION_TERMS = TERMINATION_TERMS
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
        # the probe tip (10 mm) presses a few lattice spacings of surface at most: a concentrated load, so the
        # model is built with the options it declares for one (``TissueModel.point_load_options``; a model
        # from outside the package may not declare any)
        t.options = {**tissue_options(c.model, c.integrator),
                     **getattr(model_class(c.model), "point_load_options", {})}
        if t.options.get("integrator") == "implicit":
            # stepped implicitly from the start: no explicit step for a point-load option to keep
            t.options.update(getattr(model_class(c.model), "implicit_point_load_options", {}))
        t.region_materials = None
        t.volume_options = {"size": tuple(float(s) for s in c.slab_size)}
        t.position = (0.0, 0.0, float(c.slab_size[2]) / 2.0)
        self.surface_z = float(c.slab_size[2])
        p = cfg.tool("probe")
        p.tip_radius = c.tip_radius
        p.position = (0.0, 0.0, self.surface_z + c.tip_radius + c.hover)
        cfg.dt = c.dt
        cfg.contact.stiffness_per_area = c.contact_stiffness_per_area
        cfg.contact.law = c.contact_law
        # the probe's deepest commanded tip stays this far above the floor: MuJoCo's collision detection
        # (probe vs floor, the only rigid pair) has nothing to find and is switched off
        cfg.rigid_contacts = self.surface_z - c.max_depth < RIGID_CONTACT_CLEARANCE
        require_capabilities(c.model, self.REQUIRES, self.TASK_ID)
        self.sim = Simulation(palpation_scene(cfg), dt=c.dt, substeps=self.substeps)
        stiffest = check_range(c.young_scale, "young_scale")[1] * check_range(c.stiffness_contrast, "contrast")[1]
        switch = integrator_for_range(self.sim.tissue(), c.dt, stiffest)   # inclusion: young_scale x contrast
        if switch is not None:
            # the explicit step is unstable over the stiffness range: the model steps implicitly, so the
            # point-load options that only kept its explicit step give way to its implicit ones
            t.options = {**t.options, "integrator": switch,
                         **getattr(model_class(c.model), "implicit_point_load_options", {})}
            self.sim = Simulation(palpation_scene(cfg), dt=c.dt, substeps=self.substeps)
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
            if not validate.has_length(value, 2):
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
        # the contract's only way to change stiffness; cut elements mix the two by volume fraction
        tissue.scale_material("young", inclusion_young_factors(tissue, centre, radius, contrast, scale))
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
        self.phi = self.phi_before = 0.0         # shaping potential of the running estimate (now, step start)
        self.new_cell = self.new_site = self.finished_now = False    # this step's events (reward terms)
        self.prev_tip = self.sim.tool_position("probe").copy()
        self.report_held = 0                     # consecutive control steps with report > 0
        self.guess = None
        self.error = None

    def _apply_action(self, a: np.ndarray) -> None:
        c = self.config
        self.target = probe_target(self.target.tolist(), a.tolist(), c.max_xy_step, c.xy_limit,
                                   self.surface_z + c.tip_radius, c.hover, c.max_depth)
        self.sim.set_tool_target("probe", self.target, speed=c.probe_speed)
        self.sim.step()

    def readings(self):
        """(probe position (3,) m, force on the probe (3,) N, indentation depth m), read once per
        physics state (the step's ``_update``, its terms and ``_observe`` share them; do not modify them)."""
        sim = self.sim
        key = (sim, sim.steps, self.steps)         # reset() and the unstable path clear the key
        if self._readings_key != key:
            pos = sim.tool_position("probe")
            force = sim.tool_force("probe")
            self._readings_value = (pos, force, indentation_depth(pos[2], self.surface_z, self.config.tip_radius))
            self._readings_key = key
        return self._readings_value

    def _observe(self) -> np.ndarray:
        pos, force, depth = self.readings()
        frac = self.steps / self.max_episode_steps
        est = self.estimate if self.estimate is not None else pos[:2]
        obs = np.empty(14 + self.n_cells, dtype=np.float32)
        obs[0:3] = pos
        obs[3:6] = force
        obs[6:14] = (depth, self.best[0], self.best[1], self.best[2], frac, est[0], est[1], self.contrast_seen)
        if self._map_obs is None:              # the map changes only when a sample is recorded
            self._map_obs = normalised_map(self.cell_k)
        obs[14:] = self._map_obs
        return obs

    def _update(self, a: np.ndarray) -> dict[str, Any]:
        """The step's state: peak force, best site, the stiffness sample (map cell, estimate,
        potential) and the press site of a quasi-static press, and the report hold."""
        c = self.config
        pos, force, depth = self.readings()
        self.new_cell = self.new_site = self.finished_now = False
        self.phi_before = self.phi
        fmag = vector_norm(force)
        if fmag > self.peak_force:
            self.peak_force = fmag
        k = stiffness_estimate(force[2], depth, c.press_min_depth)
        if k > self.best[2]:
            self.best = (float(pos[0]), float(pos[1]), k)
        speed = vector_norm(pos - self.prev_tip) / self.control_dt
        self.prev_tip = pos.copy()
        if k > 0.0 and speed <= c.sample_max_speed:
            self._record_sample(pos[:2].copy(), k)
        # a press site counts only when it gives a quasi-static stiffness sample (dragging a pressed tip
        # across the slab measures drag, not stiffness, and must not pay)
        if (depth >= c.press_min_depth and speed <= c.sample_max_speed
                and is_new_site(pos[:2], self.sites, c.site_spacing)):
            self.sites.append(pos[:2].copy())
            self.new_site = len(self.sites) <= c.max_rewarded_sites
        self.report_held = self.report_held + 1 if a[3] > 0.0 else 0
        return {"stiffness_estimate_N_per_m": k, "force_N": fmag,
                "estimate_xy_m": None if self.estimate is None else self.estimate.tolist()}

    def _on_terminate(self) -> dict[str, Any]:
        """The report: the guess and its error (the localisation term pays it)."""
        return self._finish(self.readings()[0])[1]

    def _record_sample(self, xy: np.ndarray, k: float) -> None:
        """Add a quasi-static stiffness sample ``k`` (N/m) at ``xy`` (m): the map cell (``new_cell``
        if it had none), the stiffness-weighted estimate, the contrast seen and the estimate's
        localisation potential ``phi``."""
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
        cell = cell_of(float(xy[0]), float(xy[1]), int(c.map_cells), float(c.map_half_width))
        if self.cell_k[cell] == 0.0:
            self.new_cell = True
        self.cell_k[cell] = max(self.cell_k[cell], k)
        self._map_obs = self._cells_sampled = None
        median = np.median(buf[1][:n])           # once for the estimate and the contrast
        self.estimate = weighted_estimate(buf[0][:n], buf[1][:n], median)
        med = float(median)
        self.contrast_seen = buf[2] / med if med > 0 else 1.0
        err = localisation_error(self.estimate, self.inclusion["centre"][:2])
        self.phi = localisation_potential(err, c.localisation_scale)

    def _finish(self, pos) -> tuple[float, dict[str, Any]]:
        """The guess (the running estimate, else the probe's (x, y)) and its error; ``(localisation
        reward, info)``."""
        c = self.config
        self.finished_now = True
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

