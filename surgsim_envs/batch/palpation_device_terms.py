"""Palpation-v0's per-step task bookkeeping for W worlds kept on the Warp device
(:class:`PalpationDeviceTerms`), the state behind ``BatchedPalpationEnv(..., device_outputs=True)``.

The per-world state (best site, previous tip, report hold, peak force, step count, the samples in
the order taken and sorted, press sites, the per-cell stiffness map, the running estimate, the
contrast seen, the potential and its value at the step's start, the guess's error, the inclusion
centre) lives in Warp arrays on the env's device; the kernels of
:mod:`surgsim_envs.batch.palpation_kernels` update it one thread per world, reading the probe's
pose and contact force from the physics arrays (:meth:`BatchSimulation.arrays`) in place. Every
:meth:`evaluate` and :meth:`observe` writes fresh output arrays: what a step returned is never
written again, so a caller may keep it (a rollout buffer) while it shares the memory through
DLPack.

Per step the host sends the clipped actions (W, 4) and the live and unstable masks (W,) and
reads back the ended flags (W,), which the autoreset needs (a reset draws the new inclusion from
each world's numpy generator, as the single env does).
"""

from __future__ import annotations

import math

import numpy as np

from surgsim_envs.batch.backend import require
from surgsim_envs.batch.device_terms import DeviceTerms
from surgsim_envs.errors import ConfigError

#: Palpation-v0's declared reward terms (name, weight field), in the order the kernel sums them
DEVICE_TERMS = (("damage", "damage_weight"), ("coverage", "cell_reward"), ("shaping", "shaping_weight"),
                ("time", "time_cost"), ("press_site", "press_reward"), ("localisation", "localisation_weight"))


class PalpationDeviceTerms(DeviceTerms):
    """The device state and kernels of ``num_worlds`` Palpation-v0 episodes (module docstring).

    sim: the env's :class:`BatchSimulation`; config: its :class:`PalpationConfig`; reward_terms:
    the env's declared terms (``RewardManager.terms``: checked against :data:`DEVICE_TERMS`);
    surface_z: m, the slab's rest surface; control_dt: s; max_episode_steps: the sample and site
    buffers' capacity.
    """

    def __init__(self, sim, config, reward_terms, surface_z: float, control_dt: float, max_episode_steps: int):
        wp, _ = require()
        from surgsim_envs.batch import palpation_kernels as K

        declared = tuple((t.name, t.weight) for t in reward_terms)
        if declared != DEVICE_TERMS:
            raise ConfigError(f"device_outputs=True computes Palpation-v0's reward terms {list(DEVICE_TERMS)} in "
                              f"Warp kernels (batch/palpation_kernels.py), but the env declares {list(declared)}; "
                              "add the new term to evaluate_step, or leave device_outputs out (the numpy path "
                              "runs the declared terms)")
        capacity = int(max_episode_steps)
        if capacity > K.pairwise_capacity():
            raise ConfigError(f"device_outputs=True keeps up to {K.pairwise_capacity()} stiffness samples per "
                              f"episode on the device, but an episode has {capacity} control steps "
                              "(episode_seconds x control_hz); shorten the episode or leave device_outputs out")
        self.wp, self.K = wp, K
        self.sim, self.device = sim, sim.device
        self.W = W = sim.W
        self.body = int(sim.tool_body["probe"])
        self.bodies = wp.array(np.asarray(sim.tool_index["probe"], dtype=np.int32), dtype=wp.int32, device=self.device)
        c = config
        p = K.PalpationParams()
        p.contact_z = float(surface_z) + c.tip_radius
        p.press_min_depth = float(c.press_min_depth)
        p.control_dt = float(control_dt)
        p.sample_max_speed = float(c.sample_max_speed)
        p.site_spacing = float(c.site_spacing)
        p.max_rewarded_sites = int(c.max_rewarded_sites)
        p.report_hold_steps = int(c.report_hold_steps)
        p.min_report_seconds = float(c.min_report_seconds)
        p.max_episode_steps = capacity
        p.map_cells = int(c.map_cells)
        p.map_half_width = float(c.map_half_width)
        p.localisation_scale = float(c.localisation_scale)
        p.tolerance = c.tolerance_mm * 1e-3
        p.success_bonus = float(c.success_bonus)
        p.damage_force = float(c.damage_force)
        for (name, field), attr in zip(DEVICE_TERMS, ("w_damage", "w_coverage", "w_shaping", "w_time", "w_press_site",
                                                      "w_localisation")):
            setattr(p, attr, float(getattr(c, field)))
        self.params = p
        self.n_cells = int(c.map_cells) ** 2
        s = K.PalpationState()
        z = lambda shape, dtype: wp.zeros(shape, dtype=dtype, device=self.device)  # noqa: E731
        s.best, s.prev_tip = z(W, wp.vec3d), z(W, wp.vec3d)
        s.report_held, s.steps = z(W, wp.int32), z(W, wp.int32)
        s.peak = z(W, wp.float64)
        s.n_samples, s.n_sites = z(W, wp.int32), z(W, wp.int32)
        s.samples_xy, s.sites = z((W, capacity), wp.vec2d), z((W, capacity), wp.vec2d)
        s.samples_k, s.sorted_k, s.weights = (z((W, capacity), wp.float64) for _ in range(3))
        s.cell_k = z((W, self.n_cells), wp.float64)
        s.has_estimate = z(W, wp.int32)
        s.estimate, s.centre = z(W, wp.vec2d), z(W, wp.vec2d)
        s.contrast, s.phi, s.phi_before, s.error = (z(W, wp.float64) for _ in range(4))
        self.state = s
        self.obs_dim = 14 + self.n_cells

    def _physics(self):
        arrays = self.sim.arrays()
        return arrays["xpos"], arrays["tool_force"]

    def reset(self, worlds: np.ndarray, centres_xy: np.ndarray) -> None:
        """A new episode in ``worlds`` with inclusion centres ``centres_xy`` (len(worlds), 2) m, the
        probe where the physics reset left it."""
        worlds = np.asarray(worlds, dtype=np.int32).reshape(-1)
        if not len(worlds):
            return
        wp = self.wp
        xpos, _ = self._physics()
        wp.launch(self.K.reset_worlds, dim=len(worlds), device=self.device,
                  inputs=[self.state, wp.array(worlds, dtype=wp.int32, device=self.device),
                          wp.array(np.ascontiguousarray(centres_xy, dtype=np.float64).reshape(-1, 2), dtype=wp.vec2d,
                                   device=self.device),
                          xpos, self.body, math.nan])

    def evaluate(self, actions: np.ndarray, live: np.ndarray, unstable: np.ndarray) -> tuple[dict, np.ndarray]:
        """The step's evaluation after the physics: ``({name: fresh device array}, ended (W,) bool on
        the host)``; names: reward, terms (6, W), terminated, truncated, ended, success, final,
        force_N, stiffness, peak, error. ``live``: the worlds that stepped their episode;
        ``unstable``: worlds that diverged and were reset this step (terminated)."""
        wp, W = self.wp, self.W
        xpos, tool_force = self._physics()
        e = lambda dtype, shape=W: wp.empty(shape, dtype=dtype, device=self.device)  # noqa: E731
        out = {"reward": e(wp.float64), "terms": e(wp.float64, (len(DEVICE_TERMS), W)), "terminated": e(wp.bool),
               "truncated": e(wp.bool), "ended": e(wp.bool), "success": e(wp.bool), "final": e(wp.float64),
               "force_N": e(wp.float64), "stiffness": e(wp.float64), "peak": e(wp.float64), "error": e(wp.float64)}
        wp.launch(self.K.evaluate_step, dim=W, device=self.device,
                  inputs=[self.state, self.params, xpos, self.body, tool_force, self.bodies,
                          self._host(actions, np.float64), self._host(live, np.int32), self._host(unstable, np.int32)],
                  outputs=[out[k] for k in ("reward", "terms", "terminated", "truncated", "ended", "success", "final",
                                            "force_N", "stiffness", "peak", "error")])
        done = out["terminated"].numpy() | out["truncated"].numpy()
        return out, done

    def observe(self):
        """(observations (W, D) float32, episode steps (W,) int64): fresh device arrays."""
        wp, W = self.wp, self.W
        xpos, tool_force = self._physics()
        obs = wp.empty((W, self.obs_dim), dtype=wp.float32, device=self.device)
        steps = wp.empty(W, dtype=wp.int64, device=self.device)
        wp.launch(self.K.observe, dim=W, device=self.device,
                  inputs=[self.state, self.params, xpos, self.body, tool_force, self.bodies], outputs=[obs, steps])
        return obs, steps
