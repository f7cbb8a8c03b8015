"""SurgSim/PalpationPress-v0: Palpation-v0 with one decision per press (PPO did not learn
Palpation-v0's per-millisecond control; one press per step is a problem it can learn).

The same slab, inclusion, randomisation and stiffness estimate as
:mod:`surgsim_envs.envs.palpation`, but one env step is one whole press: the env lifts the probe
``clearance`` m above the rest surface, moves it to the chosen site (``move_speed``), presses it
``press_depth`` m deep at ``press_speed`` and holds for ``hold_steps`` physics steps; the stiffness
sample is the mean of F_z / depth (N/m) over the last ``average_steps`` physics steps (the tissue
rings after the press). The agent decides *where* to press next and *when* to report, a few dozen
decisions per episode instead of 600 continuous-control steps (Palpation-v0 was not learned by PPO
in 400k steps: docs/training.md).

Action (3,) in [-1, 1]: ``[x, y, report]``; the press site is ``(x, y) * map_half_width`` m
(clipped to ``xy_limit``); ``report > 0`` ends the episode *instead of* pressing (honoured from
``min_presses`` presses on) and the env's stiffness-weighted estimate
(:func:`~surgsim_envs.envs.palpation.stiffness_weighted_estimate`) is the guess (also after
``max_presses`` presses).

Observation (``map_cells``\\ :sup:`2` + 13,) float32: the stiffness map (per cell the largest sample
over the largest so far, 0 = never sampled); the running estimate (x, y) m (0, 0 before a sample);
the last press site (x, y) m, its force F_z N and stiffness N/m; the stiffest cell's centre (x, y)
m; the centre (x, y) m of the next unsampled cell in boustrophedon (raster) order (the last
cell's centre once all are sampled) -- a coverage feature that makes "press where you have not
pressed" a linear function of the observation; the fraction of unsampled cells; the stiffness
contrast seen (max / median sample); the fraction of ``max_presses`` used.

Reward: ``cell_reward`` for the first sample in each map cell; ``- press_cost`` per press;
potential-based shaping on the estimate's error (as Palpation-v0; sums to ``shaping_weight *
phi_final``); ``- damage_weight`` per N of press force above ``damage_force``; at the end the
localisation reward + ``success_bonus`` if the guess is within ``tolerance_mm`` (``info["success"]``).
"""
from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from surgsim_envs.envs.palpation.env import PalpationEnv
from surgsim_envs.envs.palpation.terms import indentation_depth, stiffness_map
from surgsim_envs.envs.palpation_press.config import PalpationPressConfig
from surgsim_envs.envs.palpation_press.terms import REWARD_TERMS, TERMINATION_TERMS, cell_centre, raster_order
from surgsim_envs.envs.terms import ObsTerm
from surgsim_envs.envs.terms.action import ActionTerm


class PalpationPressEnv(PalpationEnv):
    """PalpationPress-v0 (see module docstring)."""

    config_cls = PalpationPressConfig
    TASK_ID = "SurgSim/PalpationPress-v0"
    ACTION = ActionTerm("probe", 3, "[x, y, report]: the press site over the map (x, y) and report")
    REWARD_TERMS = REWARD_TERMS
    TERMINATION_TERMS = TERMINATION_TERMS

    def _build(self) -> None:
        super()._build()
        c = self.config
        self.action_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
        lo, hi = -float(c.map_half_width), float(c.map_half_width)
        self._order = raster_order(int(c.map_cells))
        self._set_observation_terms([
            ObsTerm("stiffness_map", "1", self.n_cells, 0.0, 1.0),
            ObsTerm("estimate_xy", "m", 2, lo, hi),
            ObsTerm("last_press_xy", "m", 2, lo, hi),
            ObsTerm("last_press_force_z", "N", 1),
            ObsTerm("last_press_stiffness", "N/m", 1, 0.0),
            ObsTerm("stiffest_cell_xy", "m", 2, lo, hi),
            ObsTerm("next_unsampled_cell_xy", "m", 2, lo, hi),
            ObsTerm("unsampled_fraction", "1", 1, 0.0, 1.0),
            ObsTerm("stiffness_contrast_seen", "1", 1, 1.0),
            ObsTerm("presses_fraction", "1", 1, 0.0, 1.0)])

    @property
    def max_episode_steps(self) -> int:
        return int(self.config.max_presses)

    def _randomise(self, options: dict[str, Any]) -> None:
        super()._randomise(options)
        self.last = (0.0, 0.0, 0.0, 0.0)     # x, y, F_z, k of the last press
        self.reported = False
        self.sim.set_tool_target("probe", self._hover_target(self.home[:2]), speed=self.config.move_speed)

    def _hover_target(self, xy) -> np.ndarray:
        return np.array([xy[0], xy[1], self.surface_z + self.config.tip_radius + self.config.clearance])

    # -- one press ------------------------------------------------------------------------------
    def _apply_action(self, a: np.ndarray) -> None:
        c = self.config
        self.reported = bool(a[2] > 0.0) and self.steps > c.min_presses
        if self.reported:
            return
        sim, probe = self.sim, "probe"
        site = np.clip(a[:2] * c.map_half_width, -c.xy_limit, c.xy_limit)
        here = sim.tool_position(probe)
        sim.set_tool_target(probe, self._hover_target(here[:2]), speed=c.move_speed)     # lift
        lift = max(0.0, self._hover_target(here[:2])[2] - here[2])
        travel = float(np.hypot(*(site - here[:2])))
        sim.physics_step(int(np.ceil(lift / c.move_speed / sim.dt)))       # nothing read: one batched call
        sim.set_tool_target(probe, self._hover_target(site), speed=c.move_speed)
        sim.physics_step(int(np.ceil(travel / c.move_speed / sim.dt)) + c.settle_steps)
        bottom = np.array([site[0], site[1], self.surface_z + c.tip_radius - c.press_depth])
        sim.set_tool_target(probe, bottom, speed=c.press_speed)
        fz, depth, fmax = [], [], 0.0
        for i in range(c.hold_steps):
            sim.physics_step()
            f = sim.tool_force(probe)
            fmax = max(fmax, float(np.linalg.norm(f)))
            if i >= c.hold_steps - c.average_steps:
                fz.append(float(f[2]))
                depth.append(indentation_depth(sim.tool_position(probe)[2], self.surface_z, c.tip_radius))
        self.press_peak = fmax
        self.peak_force = max(self.peak_force, fmax)
        d = float(np.mean(depth))
        k = float(np.mean(fz)) / d if d >= c.press_min_depth else 0.0
        # The probe's measured position trails its target by a contact-friction lag (a few um
        # past a map edge): clip it to the map the observation space declares.
        hw = float(c.map_half_width)
        x, y = np.clip(sim.tool_position(probe)[:2], -hw, hw)
        self.last = (float(x), float(y), float(np.mean(fz)), k)

    # -- observation ----------------------------------------------------------------------------
    def _next_unsampled(self) -> np.ndarray:
        c = self.config
        free = [i for i in self._order if self.cell_k[i] == 0.0]
        return cell_centre(int(free[0] if free else self._order[-1]), int(c.map_cells), c.map_half_width)

    def _observe(self) -> np.ndarray:
        c = self.config
        est = self.estimate if self.estimate is not None else np.zeros(2)
        stiffest = (cell_centre(int(np.argmax(self.cell_k)), int(c.map_cells), c.map_half_width)
                    if self.cell_k.any() else np.zeros(2))
        return np.array([*stiffness_map(self.cell_k), est[0], est[1], self.last[0], self.last[1], self.last[2],
                         self.last[3], stiffest[0], stiffest[1], *self._next_unsampled(),
                         float(np.mean(self.cell_k == 0.0)), self.contrast_seen,
                         min(1.0, self.steps / c.max_presses)], dtype=np.float32)

    # -- step state (the terms in .terms read it) -----------------------------------------------
    def _update(self, a: np.ndarray) -> dict[str, Any]:
        """The press's stiffness sample (site, map cell, estimate, potential); nothing on a report."""
        self.new_cell = self.finished_now = False
        self.phi_before = self.phi
        if self.reported:
            return {}
        x, y, fz, k = self.last
        if k > 0.0:
            xy = np.array([x, y])
            self.sites.append(xy)
            if k > self.best[2]:
                self.best = (x, y, k)
            self._record_sample(xy, k)
        return {"press_force_z_N": fz, "stiffness_estimate_N_per_m": k,
                "estimate_xy_m": None if self.estimate is None else self.estimate.tolist()}

    def _on_terminate(self) -> dict[str, Any]:
        """The report: the guess and its error (the localisation term pays it)."""
        return self._finish(self.sim.tool_position("probe"))[1]
