"""Palpation-v0 as a Gymnasium vector env over W batched worlds (:class:`BatchedPalpationEnv`, on
:class:`~surgsim_envs.batch.env.BatchedTaskEnv`).

``gym.make_vec("SurgSim/Palpation-v0", num_envs=W, vectorization_mode="vector_entry_point",
device="cpu")`` returns it (``device="cuda"`` where a GPU exists). The physics of all worlds runs
in :class:`~surgsim_envs.batch.simulation.BatchSimulation`; every world is one Palpation-v0
episode with the single env's observation (same names and order, ``observation_names``), reward
terms and info metrics, computed by the task's own term functions (:mod:`surgsim_envs.envs.palpation`)
on the per-world arrays:

* physics readouts and the per-step terms (indentation depth, force magnitude, damage penalty,
  stiffness estimate, quasi-static test, report hold, time cost) are numpy operations over all worlds;
* the stiffness-sample bookkeeping (press sites, map cells, the running stiffness-weighted
  estimate and its shaping) runs per world that took a sample this step.

Per-world randomisation as the single env's ``reset``: inclusion position, depth, radius,
stiffness contrast and Young's scale, drawn from each world's own generator (the base's seeding:
world i of ``reset(seed=s)`` has the inclusion of ``gym.make("SurgSim/Palpation-v0").reset(seed=s + i)``);
they enter the tissue as per-tet Young's factors, computed on the device for the reset worlds
(:class:`~surgsim_envs.batch.inclusions.SphereInclusionFactors`,
:meth:`BatchSimulation.set_young_factor_array`: the single env's volume-fraction lump).
Autoreset, diverged worlds and the device arrays: the base's.

``device_outputs=True`` (``gym.make_vec(..., device="cpu", device_outputs=True)``) moves the
per-step bookkeeping, observation and reward terms onto the Warp device: the kernels of
:mod:`surgsim_envs.batch.palpation_kernels` on the state of
:class:`~surgsim_envs.batch.palpation_device_terms.PalpationDeviceTerms`, one thread per world,
the same arithmetic as the numpy path. ``step`` and ``reset`` then return observations (W, D)
float32, rewards (W,) float64, terminated and truncated (W,) bool as fresh Warp arrays on the
device (``__dlpack__``: ``torch.from_dlpack``, ``jax.dlpack.from_dlpack``, ``np.from_dlpack`` share
them), and ``info``'s ``reward_terms``, ``final_reward``, ``force_N``,
``stiffness_estimate_N_per_m``, ``peak_force_N``, ``steps``, ``localisation_error_m``,
``success`` / ``is_success`` (with their ``_`` masks, the worlds whose episode ended this step;
present every step) as device arrays too. The reset info (the inclusions drawn on the host) and
``info["unstable"]`` (a diverged world, found on the host) stay numpy.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import warp as wp

from surgsim_envs.batch.env import BatchedTaskEnv
from surgsim_envs.batch.inclusions import SphereInclusionFactors
from surgsim_envs.batch.palpation_device_terms import PalpationDeviceTerms
from surgsim_envs.envs.checks import sample
from surgsim_envs.envs.palpation import (PalpationEnv, is_new_site, localisation_error,
                                         localisation_reward, map_cell, stiffness_map,
                                         stiffness_weighted_estimate)
from surgsim_envs.envs.palpation.terms import localisation_potential
from surgsim_envs.errors import ConfigError


class _WorldTask:
    """One world's episode bookkeeping (the single env's per-episode attributes)."""

    def __init__(self, n_cells: int):
        self.n_cells = n_cells

    def start(self, inclusion: dict, prev_tip: np.ndarray) -> None:
        self.inclusion = inclusion
        self.sites: list[np.ndarray] = []
        self.samples_xy: list[np.ndarray] = []
        self.samples_k: list[float] = []
        self.estimate = None
        self.contrast_seen = 1.0
        self.cell_k = np.zeros(self.n_cells)
        self.phi = self.phi_before = 0.0
        self.new_cell = self.new_site = self.finished_now = False
        self.guess = None
        self.error = None

    def begin_step(self) -> None:
        """Clear the step's events and keep the potential at the step's start (the single env's ``_update``)."""
        self.new_cell = self.new_site = self.finished_now = False
        self.phi_before = self.phi


class BatchedPalpationEnv(BatchedTaskEnv):
    """Palpation-v0 in ``num_envs`` batched worlds on Warp device ``device`` (module docstring).

    num_envs: worlds W; device: "cpu" (Warp's CPU device, everywhere) or "cuda"; config / overrides:
    as for ``gym.make("SurgSim/Palpation-v0", ...)`` (a :class:`PalpationConfig` and field overrides).
    """

    TEMPLATE = PalpationEnv
    #: the batched kernels step the explicit mass-spring network; the single env's default is the
    #: quasi-static FEM at 5 mm (a factorised stiffness per world is not batched yet), so a batch
    #: builds the task on the 10 mm mass_spring lattice unless told otherwise (docs/batch.md)
    BATCHED_DEFAULTS = {"model": "mass_spring", "spacing": 0.01}
    DEVICE_OUTPUTS = True

    def __init__(self, num_envs: int = 1, *, device: str = "cpu", config=None, max_episode_steps: int | None = None,
                 device_outputs: bool = False, **overrides):
        super().__init__(num_envs, device=device, config=config, max_episode_steps=max_episode_steps,
                         device_outputs=device_outputs, **overrides)
        W, c = self.num_envs, self.config
        self.surface_z = self.template.surface_z
        self.home = np.array(self.template.home, dtype=np.float64)
        # the template's tets: the mesh the inclusion is cut from, its factors computed on the device
        self._inclusions = SphereInclusionFactors(self.template.sim.tissue().element_vertices(), self.sim.device)
        self.n_cells = int(c.map_cells) ** 2
        self._tasks = [_WorldTask(self.n_cells) for _ in range(W)]
        self._target = np.tile(self.home, (W, 1))
        self._best = np.zeros((W, 3))
        self._prev_tip = np.tile(self.home, (W, 1))
        self._report_held = np.zeros(W, dtype=np.int64)
        self._peak = np.zeros(W)
        self._device_terms = (PalpationDeviceTerms(self.sim, c, self.rewards.terms, self.surface_z, self.control_dt,
                                                   self.max_episode_steps) if self.device_outputs else None)

    def _reset_worlds(self, idx: np.ndarray, options: dict[str, Any]) -> None:
        """Randomise and reset worlds ``idx`` as the single env's reset does (same draws, same order)."""
        c = self.config
        get = lambda k: options.get(k, getattr(c, k))  # noqa: E731
        half = float(min(c.slab_size[:2])) / 2
        sim = self.sim
        sim.reset_worlds(idx)
        lumps = []                          # (centre, radius, contrast, scale) per reset world
        for w in idx:
            task = self._tasks[w]
            rng = self._rngs[w]
            x = sample(rng, get("inclusion_xy"), "inclusion_xy", -half, half)
            y = sample(rng, get("inclusion_xy"), "inclusion_xy", -half, half)
            if options.get("inclusion_position") is not None:
                value = np.asarray(options["inclusion_position"], dtype=float).reshape(-1)
                if value.shape != (2,) or not np.all(np.abs(value) <= half):
                    raise ConfigError(f"inclusion_position must be (x, y) m inside +-{half} m, got {value.tolist()}")
                x, y = float(value[0]), float(value[1])
            depth = sample(rng, get("inclusion_depth"), "inclusion_depth", 0.0, float(c.slab_size[2]))
            radius = sample(rng, get("inclusion_radius"), "inclusion_radius", 1e-4, float(max(c.slab_size)))
            contrast = sample(rng, get("stiffness_contrast"), "stiffness_contrast", 1.0, 20.0)
            scale = sample(rng, get("young_scale"), "young_scale", 0.1, 10.0)
            rng.integers(2**31)             # the single env's physics seed draw: keeps the streams aligned
            centre = np.array([x, y, self.surface_z - depth])
            lumps.append((centre, radius, contrast, scale))
            task.start({"centre": centre, "radius": radius, "contrast": contrast, "young_scale": scale},
                       self.home.copy())
        if len(idx):
            centres, radii, contrasts, scales = zip(*lumps)
            factors = self._inclusions.factors(np.array(centres), radii, contrasts, scales)
            worlds = wp.array(np.asarray(idx, dtype=np.int32), dtype=wp.int32, device=sim.device)
            sim.set_young_factor_array(factors, worlds)
        self._target[idx] = self.home
        sim.set_tool_targets("probe", self._target[idx], speed=c.probe_speed, worlds=idx)
        self._steps[idx] = 0
        self._best[idx] = 0.0
        self._prev_tip[idx] = sim.tool_positions("probe")[idx]
        self._report_held[idx] = 0
        self._peak[idx] = 0.0
        self._readings = None
        if self._device_terms is not None:
            self._device_terms.reset(idx, np.array([self._tasks[w].inclusion["centre"][:2] for w in idx]))

    # -- stepping ---------------------------------------------------------------------------------
    def _apply_actions(self, a: np.ndarray, live: np.ndarray) -> None:
        """Probe targets as the single env's ``_apply_action``, for the live worlds."""
        c = self.config
        xy = np.clip(self._target[:, :2] + a[:, :2] * c.max_xy_step, -c.xy_limit, c.xy_limit)
        press = (a[:, 2] + 1.0) / 2.0
        z = self.surface_z + c.tip_radius + c.hover - press * (c.hover + c.max_depth)
        self._target[live, :2] = xy[live]
        self._target[live, 2] = z[live]
        self.sim.set_tool_targets("probe", self._target[live], speed=c.probe_speed, worlds=np.flatnonzero(live))

    def _read(self):
        if self._readings is None:
            pos = self.sim.tool_positions("probe")
            force = self.sim.tool_forces("probe")
            depth = np.maximum(0.0, self.surface_z + self.config.tip_radius - pos[:, 2])   # indentation_depth
            self._readings = (pos, force, depth)
        return self._readings

    def _evaluate(self, a: np.ndarray, live: np.ndarray):
        c, W = self.config, self.num_envs
        pos, force, depth = self._read()
        fmag = np.sqrt(np.einsum("ij,ij->i", force, force))
        self._peak = np.where(live, np.maximum(self._peak, fmag), self._peak)
        for w in np.flatnonzero(live):
            self._tasks[w].begin_step()
        pressing = depth >= c.press_min_depth
        k = np.where(pressing, force[:, 2] / np.where(pressing, depth, 1.0), 0.0)      # stiffness_estimate
        better = live & (k > self._best[:, 2])
        self._best[better] = np.column_stack([pos[better, 0], pos[better, 1], k[better]])
        d = pos - self._prev_tip
        speed = np.sqrt(np.einsum("ij,ij->i", d, d)) / self.control_dt
        self._prev_tip = np.where(live[:, None], pos, self._prev_tip)
        quasi_static = speed <= c.sample_max_speed
        for w in np.flatnonzero(live & (k > 0.0) & quasi_static):
            self._record_sample(w, pos[w, :2].copy(), float(k[w]))
        for w in np.flatnonzero(live & pressing & quasi_static):
            task = self._tasks[w]
            if is_new_site(pos[w, :2], task.sites, c.site_spacing):
                task.sites.append(pos[w, :2].copy())
                task.new_site = len(task.sites) <= c.max_rewarded_sites
        self._report_held = np.where(a[:, 3] > 0.0, self._report_held + 1, 0)
        terminated = live & (self._report_held >= c.report_hold_steps) & (self._steps * self.control_dt >= c.min_report_seconds)
        truncated = live & ~terminated & (self._steps >= self.max_episode_steps)
        final = np.zeros(W)
        for w in np.flatnonzero(terminated | truncated):
            r = self._finish(w, pos[w])
            if terminated[w]:
                self._tasks[w].finished_now = True       # the localisation term pays the report
            else:
                final[w] = r                             # as the single env's "final" entry
        view, tasks = self._view, self._tasks

        def view_of(w):
            t = tasks[w]
            return view.point((pos[w], force[w], float(depth[w])), new_cell=t.new_cell, new_site=t.new_site,
                              finished_now=t.finished_now, phi=t.phi, phi_before=t.phi_before, error=t.error,
                              steps=int(self._steps[w]), report_held=int(self._report_held[w]))

        reward, terms = self._term_loop(live, view_of)      # the single env's term functions, in declared order
        reward = reward + final
        for name in terms:
            terms[name] = np.where(live, terms[name], 0.0)
        info = {"reward_terms": terms, "final_reward": final, "force_N": fmag, "stiffness_estimate_N_per_m": k,
                "peak_force_N": self._peak.copy(), "steps": self._steps.copy()}
        ended = terminated | truncated
        if ended.any():
            err = np.array([t.error if t.error is not None else math.nan for t in self._tasks])
            info["localisation_error_m"], info["_localisation_error_m"] = err, ended.copy()
            ok = ended & (err <= c.tolerance_mm * 1e-3)
            info["success"], info["_success"] = ok, ended.copy()
            info["is_success"], info["_is_success"] = ok.copy(), ended.copy()
        return np.where(live, reward, 0.0), terminated, truncated, info

    def _record_sample(self, w: int, xy: np.ndarray, k: float) -> None:
        """The single env's sample bookkeeping for world ``w`` (coverage, estimate, contrast, shaping)."""
        c, task = self.config, self._tasks[w]
        task.samples_xy.append(xy)
        task.samples_k.append(k)
        cell = map_cell(xy, int(c.map_cells), float(c.map_half_width))
        if task.cell_k[cell] == 0.0:
            task.new_cell = True
        task.cell_k[cell] = max(task.cell_k[cell], k)
        ks = np.array(task.samples_k)
        task.estimate = stiffness_weighted_estimate(np.array(task.samples_xy), ks)
        med = float(np.median(ks))
        task.contrast_seen = float(ks.max()) / med if med > 0 else 1.0
        err = localisation_error(task.estimate, task.inclusion["centre"][:2])
        task.phi = localisation_potential(err, c.localisation_scale)

    def _finish(self, w: int, pos: np.ndarray) -> float:
        c, task = self.config, self._tasks[w]
        task.guess = (task.estimate if task.estimate is not None else pos[:2]).copy()
        task.error = localisation_error(task.guess, task.inclusion["centre"][:2])
        return localisation_reward(task.error, c.localisation_scale, c.tolerance_mm * 1e-3, c.localisation_weight,
                                   c.success_bonus)

    def _device_step(self, a: np.ndarray, live: np.ndarray, unstable: np.ndarray):
        terms = self._device_terms
        out, done = terms.evaluate(a, live & ~unstable, unstable & live)    # as the base: an autoreset world is not terminated
        done_before = np.flatnonzero(self._autoreset)
        if len(done_before):                  # not live this step: reward 0, not terminated nor truncated
            self._reset_worlds(done_before, {})
        self._autoreset = done
        obs, steps = terms.observe()
        ended = out["ended"]
        info = {"reward_terms": {name: out["terms"][j] for j, name in enumerate(self.reward_term_names)},
                "final_reward": out["final"], "force_N": out["force_N"],
                "stiffness_estimate_N_per_m": out["stiffness"], "peak_force_N": out["peak"], "steps": steps,
                "localisation_error_m": out["error"], "_localisation_error_m": ended,
                "success": out["success"], "_success": ended, "is_success": out["success"], "_is_success": ended}
        if unstable.any():
            info["unstable"], info["_unstable"] = unstable.copy(), unstable.copy()
        return obs, out["reward"], out["terminated"], out["truncated"], info

    def _observe(self):
        if self._device_terms is not None:
            return self._device_terms.observe()[0]
        pos, force, depth = self._read()
        obs = self._obs
        obs[:, 0:3] = pos
        obs[:, 3:6] = force
        obs[:, 6] = depth
        obs[:, 7:10] = self._best
        obs[:, 10] = self._steps / self.max_episode_steps
        for w, task in enumerate(self._tasks):
            est = task.estimate if task.estimate is not None else pos[w, :2]
            obs[w, 11:13] = est
            obs[w, 13] = task.contrast_seen
            obs[w, 14:] = stiffness_map(task.cell_k)
        return obs.copy()

    def _reset_info(self, idx) -> dict:
        centres = np.array([t.inclusion["centre"] for t in self._tasks])
        return {"inclusion_centre_m": centres, "inclusion_radius_m": np.array([t.inclusion["radius"] for t in self._tasks]),
                "stiffness_contrast": np.array([t.inclusion["contrast"] for t in self._tasks])}
