"""Slippage-v0 as a Gymnasium vector env over W batched worlds (:class:`BatchedSlippageEnv`, on
:class:`~surgsim_envs.batch.env.BatchedTaskEnv`).

``gym.make_vec("SurgSim/Slippage-v0", num_envs=W, vectorization_mode="vector_entry_point",
device="cpu")`` returns it. Every world is one Slippage-v0 episode (:mod:`surgsim_envs.envs.slippage`)
with the single env's observation (12 entries), reward and termination terms (``SlippageEnv.REWARD_TERMS``
/ ``TERMINATION_TERMS`` on a :class:`~surgsim_envs.batch.world_view.WorldView`) and info metrics:

* the along-axis wrist drive is the template's force motor (its MuJoCo model, changed by the single
  env, is what MuJoCo Warp steps); the jaw closure and the pull run as a per-world control schedule
  (:meth:`BatchSimulation.step_with_controls`, computed per world with the single env's compiled
  :func:`~surgsim_envs.envs.slippage.terms.control_schedule`), not through the rate limiter;
* the reset's settle: the contact-free approach is recorded once on the template's CPU scene
  (:class:`~surgsim_envs.scene.approach_snapshot.ApproachSnapshot`) and restored into the reset
  worlds (:meth:`BatchSimulation.set_rigid_states`); the rest of the settle (jaws closing on the
  organ) is simulated. When only a few worlds reset (autoreset), they settle in a small batch of
  the scene whose worlds are then copied in (:meth:`BatchSimulation.copy_worlds_from`), and the
  other worlds do not step; when many reset, in the batch itself, the others held
  (:meth:`BatchSimulation.held`) while the reset worlds settle;
* the slip tracker, the pull, the squeeze and the loss of grasp of the single env's ``_update`` run
  per live world on the host.

``device_outputs=True`` (``gym.make_vec(..., device="cpu", device_outputs=True)``) moves the
control step's jaw and pull schedule (a Warp kernel per world from the per-world pull parameters
and a float64 clock on the device, stepped without a host copy), the per-step bookkeeping (slip
tracker, pull and squeeze readouts, loss of grasp, truncation, success), the observation and the
reward terms onto the Warp device: the kernels of :mod:`surgsim_envs.batch.slippage_kernels` on the
state of :class:`~surgsim_envs.batch.slippage_device_terms.SlippageDeviceTerms`, one thread per
world, the same arithmetic as the numpy path. ``step`` and ``reset`` then return observations
(W, 12) float32, rewards (W,) float64, terminated and truncated (W,) bool as fresh Warp arrays on
the device, and the info entries (``reward_terms``, ``steps``, ``pull_force_N``,
``normal_force_N``, ``least_squeeze_N``, ``dropped``, ``success`` / ``is_success``, ``mu``,
``mu_static``, ``young_scale``, ``slip_distance_m``, ``peak_force_N``) as device arrays too;
``info["unstable"]`` (a diverged world, found on the host) stays numpy. A reset stays on the host
(each world's draws from its numpy generator, the settle's schedule) and starts the episode on the
device.

Per-world randomisation in the single env's order from each world's generator: friction, Young's
modulus scale, the physics seed draw, pull rate, amplitude, frequency, phase. The ``organ`` option
is refused (a batch holds one mesh).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from surgsim_envs.batch.env import BatchedTaskEnv
from surgsim_envs.batch.simulation import BatchSimulation
from surgsim_envs.batch.slippage_device_terms import SlippageDeviceTerms
from surgsim_envs.envs.checks import sample
from surgsim_envs.envs.grasp.terms import SlipTracker
from surgsim_envs.envs.slippage import SlippageEnv
from surgsim_envs.envs.slippage.terms import control_schedule, least_squeeze
from surgsim_envs.envs.terms.action import jaw_closure
from surgsim_envs.envs.terms.termination import any_terminated
from surgsim_envs.errors import ConfigError
from surgsim_envs.scene.approach_snapshot import ApproachSnapshot


class _SlippageWorld:
    """One world's episode state under the single env's attribute names (SlippageEnv)."""

    def __init__(self):
        self.slip = SlipTracker()
        self.mu = self.young_scale = 0.0
        self.rate = self.amplitude = self.frequency = self.phase = self.t0 = 0.0
        self.pull = self.slip_distance = self.slip_before = self.normal_total = self.peak_force = 0.0
        self.jaw_goal = 0.0
        self.lost = False
        self.pos0 = np.zeros(3)


class BatchedSlippageEnv(BatchedTaskEnv):
    """Slippage-v0 in ``num_envs`` batched worlds on Warp device ``device`` (module docstring)."""

    TEMPLATE = SlippageEnv
    DEVICE_OUTPUTS = True
    REFUSED = {"organ": "it changes the tissue mesh and a batch holds one mesh for all worlds; build the batched "
                        "env with the organ in its config (gym.make_vec(..., organ=...)) instead"}

    def __init__(self, num_envs: int = 1, *, device: str = "cpu", config=None, max_episode_steps: int | None = None,
                 device_outputs: bool = False, **overrides):
        super().__init__(num_envs, device=device, config=config, max_episode_steps=max_episode_steps,
                         device_outputs=device_outputs, **overrides)
        t, c = self.template, self.config
        tsim = t.sim
        tool = tsim.tool(t.tool_name)
        self.tool_name = t.tool_name
        self.gcfg = g = tool.config
        self.pull_dir = np.array(t.pull_dir, dtype=np.float64)
        self.acts = [int(tool.jaw_actuator_id), int(tool.actuator_ids[2])]   # jaw, pull (the task's choice)
        self.n = tsim.tissue_subcycles
        self.rigid_dt = tsim.dt * self.n
        self.settle_goal = jaw_closure(c.initial_closure, g.open_radius, g.min_radius)
        self.settle_steps = int(round(c.settle_time / tsim.dt))
        self._snapshot, self._snapshot_steps = None, 0
        if c.replay_approach:
            approach = ApproachSnapshot()
            key = ("settle", self.settle_goal, self.settle_steps)

            def run(k: int) -> None:        # the template's settle schedule on its CPU scene
                v = self._schedule(k // self.n, float(tsim.data.ctrl[self.acts[0]]), tsim.time, self.settle_goal)
                tsim.step_with_controls(self.acts, v)

            tsim.reset()
            self._snapshot_steps = approach.skip(tsim, key, run, self.settle_steps)
            self._snapshot = approach.state(tsim, key)
            tsim.reset()
        self._worlds = [_SlippageWorld() for _ in range(self.num_envs)]
        self._clock = np.zeros(self.num_envs)
        self._settle_batches: dict[int, BatchSimulation] = {}
        self._pending = None
        self._device_terms = (SlippageDeviceTerms(self.sim, c, self.rewards.terms, tool, self.tool_name, self.acts,
                                                  self.pull_dir, self.rigid_dt, self.max_episode_steps)
                              if self.device_outputs else None)
        self._device_metrics = None

    def _schedule(self, steps: int, jaw: float, t: float, goal: float, world: _SlippageWorld | None = None):
        """(steps, 2) jaw and pull controls of one world (the single env's ``_run``); no world: no pull."""
        c = self.config
        v = np.zeros((steps, 2))           # no pull: column 1 stays 0 (control_schedule leaves it)
        lim = c.closing_speed * self.rigid_dt
        if world is None:
            control_schedule(v, jaw, goal, lim, t, self.rigid_dt, False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        else:
            control_schedule(v, jaw, goal, lim, t, self.rigid_dt, True, world.rate, world.amplitude, world.frequency,
                             world.phase, world.t0, float(c.max_pull))
        return v

    # -- episodes ---------------------------------------------------------------------------------
    def _reset_worlds(self, idx: np.ndarray, options: dict[str, Any]) -> None:
        """Randomise worlds ``idx`` as the single env's ``_randomise`` (same draws, same order), then
        settle them (snapshot restore plus the simulated rest): a few in a small batch copied in, many
        in the batch itself with the other worlds held."""
        c, sim = self.config, self.sim
        idx = np.asarray(idx, dtype=np.int64)
        mu, scale = np.zeros(len(idx)), np.zeros(len(idx))
        for k, w in enumerate(idx):
            rng, wd = self._rngs[w], self._worlds[w]
            mu[k] = sample(rng, options.get("mu", c.mu), "mu", 0.0, 2.0)
            scale[k] = sample(rng, options.get("young_scale", c.young_scale), "young_scale", 0.5, 1.25)
            rng.integers(2**31)             # the single env's physics seed draw: keeps the streams aligned
            wd.rate = sample(rng, options.get("pull_rate", c.pull_rate), "pull_rate", 0.0, 10.0)
            wd.amplitude = sample(rng, options.get("pull_amplitude", c.pull_amplitude), "pull_amplitude", 0.0, 10.0)
            wd.frequency = sample(rng, options.get("pull_frequency", c.pull_frequency), "pull_frequency", 0.0, 50.0)
            wd.phase = float(rng.uniform(0.0, 2.0 * math.pi))
            wd.mu, wd.young_scale = float(mu[k]), float(scale[k])
        settle = self._settle_batch(len(idx))
        if settle is None:                  # many reset: they settle in the batch itself, the others held
            with sim.held(np.setdiff1d(np.arange(self.num_envs), idx)):
                self._clock[idx] = self._settle(sim, idx, mu, scale)
        else:                               # a few: in a small batch, then copied in; the others do not step
            rows = np.minimum(np.arange(settle.W), len(idx) - 1)     # extra rows repeat the last world's draws
            self._clock[idx] = self._settle(settle, np.arange(settle.W), mu[rows], scale[rows])
            sim.copy_worlds_from(settle, np.arange(len(idx)), idx)
        self._steps[idx] = 0
        self._readings = None
        if self._device_terms is not None:
            self._start_on_device(idx)
            return
        pos = sim.tool_positions(self.tool_name)
        mask = sim.contact_node_mask().numpy()
        x = sim.tissue_positions()
        t = self._times()
        for w in idx:
            wd = self._worlds[w]
            nodes = np.flatnonzero(mask[w])
            if len(nodes) == 0:
                raise ConfigError("Slippage: the jaws closed on nothing during the settle; raise initial_closure")
            wd.slip.reset()
            wd.slip.start(pos[w], x[w], nodes)
            wd.t0 = float(t[w])
            wd.pos0 = pos[w].copy()
            wd.jaw_goal = self.settle_goal
            wd.pull = wd.slip_distance = wd.slip_before = wd.normal_total = wd.peak_force = 0.0
            wd.lost = False

    def _settle(self, sim, rows: np.ndarray, mu: np.ndarray, scale: np.ndarray) -> float:
        """Worlds ``rows`` of batch ``sim`` reset, given friction ``mu`` and Young's scale ``scale``,
        and settled as the single env's reset: the recorded approach restored, then the jaws' closure
        simulated. Returns the simulated time (s, float64) the settle ends at."""
        c = self.config
        sim.reset_worlds(rows)
        sim.set_tool_friction(mu, c.static_friction_ratio * mu, worlds=rows)
        sim.set_young_factors(np.repeat(scale[:, None], sim.material_tets, axis=1), worlds=rows)
        done, t0 = 0, 0.0
        if self._snapshot is not None and 0 < self._snapshot_steps <= self.settle_steps:
            sim.set_rigid_states(self._snapshot, worlds=rows)
            done = self._snapshot_steps
            t0 = float(self._snapshot[0])       # mjSTATE_TIME comes first
        K = -(-(self.settle_steps - done) // self.n)
        jaw = sim.controls(self.acts[:1])[:, 0]
        values = np.zeros((K, sim.W, 2))
        for w in rows:                      # worlds not in rows (held by the caller) keep zeros
            values[:, w] = self._schedule(K, float(jaw[w]), t0, self.settle_goal)
        sim.step_with_controls(self.acts, values)
        t = t0
        for _ in range(K):                  # MuJoCo's float64 time update, d.time += h, per step
            t += self.rigid_dt
        return t

    def _settle_batch(self, k: int):
        """A batch of the scene with the smallest power of two >= k worlds, for the settles of k
        reset worlds (built at first use), or None when that is not smaller than this batch."""
        size = 1 << (int(k) - 1).bit_length()
        if size >= self.num_envs:
            return None
        if size not in self._settle_batches:
            self._settle_batches[size] = BatchSimulation(self.template.sim, size, device=self.sim.device,
                                                         graphs=self.sim.graphs.mode)
        return self._settle_batches[size]

    def _start_on_device(self, idx: np.ndarray) -> None:
        """The reset worlds' episodes on the device (device_outputs): their draws and clocks, the slip
        tracker on the contacted nodes (the numpy path's ``slip.start`` in a kernel)."""
        ws = [self._worlds[w] for w in idx]
        f = lambda name: np.array([getattr(wd, name) for wd in ws])  # noqa: E731
        counts = self._device_terms.reset(idx, self._clock[idx], f("mu"), f("young_scale"), f("rate"), f("amplitude"),
                                          f("frequency"), f("phase"))
        if not np.all(counts > 0):
            raise ConfigError("Slippage: the jaws closed on nothing during the settle; raise initial_closure")

    def _times(self) -> np.ndarray:
        """(W,) s, each world's simulation time in float64 as the CPU scene's ``d.time`` (MuJoCo
        Warp's own is float32): zero at reset, the snapshot's time after its restore, plus the MuJoCo
        step per step."""
        return self._clock.copy()

    def _reset_info(self, idx) -> dict:
        if self._device_terms is not None:
            return {k: v for k, v in self._device_metrics.items() if k != "steps"}
        return self._metrics()

    # -- stepping ---------------------------------------------------------------------------------
    def _apply_actions(self, a: np.ndarray, live: np.ndarray) -> None:
        """The live worlds' jaw goals and the episode's pull, as the single env's ``_apply_action``; the
        other worlds keep their controls."""
        g, sim = self.gcfg, self.sim
        K = -(-self.substeps // self.n)
        if self._device_terms is not None:      # the schedule is computed on the device (_physics)
            self._pending = (a[:, 0].copy(), live.copy())
            return
        ctrl = sim.controls(self.acts)
        t = self._times()
        values = np.repeat(ctrl[None], K, axis=0)
        for w in np.flatnonzero(live):
            wd = self._worlds[w]
            wd.jaw_goal = jaw_closure(float(a[w, 0]), g.open_radius, g.min_radius)
            values[:, w] = self._schedule(K, float(ctrl[w, 0]), float(t[w]), wd.jaw_goal, wd)
            if K:
                wd.pull = float(values[-1, w, 1])
        self._pending = values

    def _physics(self) -> None:
        """The control step's schedule (:meth:`_apply_actions`; worlds without an action hold their
        controls) in every world."""
        values = self._pending
        if self._device_terms is not None:
            a, live = values if values is not None else (np.zeros(self.num_envs), np.zeros(self.num_envs, dtype=bool))
            self._pending = None
            K = -(-self.substeps // self.n)
            self.sim.step_with_control_array(self.acts, self._device_terms.schedule(K, a, live))
            return
        if values is None:
            K = -(-self.substeps // self.n)
            values = np.repeat(self.sim.controls(self.acts)[None], K, axis=0)
        self._pending = None
        self._run(values, np.arange(self.num_envs))

    def _run(self, values: np.ndarray, worlds: np.ndarray) -> None:
        """The schedule ``values`` (K, W, 2) in every world; the clocks of ``worlds`` advance (the
        others are held by the caller)."""
        self.sim.step_with_controls(self.acts, values)
        for _ in range(len(values)):        # MuJoCo's float64 time update, d.time += h, per step
            self._clock[worlds] += self.rigid_dt

    def _read(self):
        if self._readings is None:
            sim, name = self.sim, self.tool_name
            jaws = sim.jaw_forces(name)
            self._readings = (sim.tool_positions(name), jaws["normal"], jaws["tangential"],
                              sim.tool_contact_report(name), sim.jaw_openings(name))
        return self._readings

    def _world_readings(self, w: int) -> tuple:
        pos, fn, ft, rep, _ = self._read()
        return pos[w], fn[w], ft[w], {k: (int(v[w]) if k in ("contacts", "slipping") else float(v[w]))
                                      for k, v in rep.items()}

    def _evaluate(self, a: np.ndarray, live: np.ndarray):
        c, W = self.config, self.num_envs
        x = self.sim.tissue_positions()
        per_world = {}
        terminated = np.zeros(W, dtype=bool)
        for w in np.flatnonzero(live):
            wd = self._worlds[w]
            r = per_world[w] = self._world_readings(w)
            pos, fn, _, rep = r
            wd.slip_before = wd.slip_distance
            wd.slip_distance = wd.slip.distance(pos, x[w])
            wd.normal_total = total = float(np.sum(fn))
            wd.peak_force = max(wd.peak_force, total)
            wd.lost = rep["contacts"] == 0 or wd.slip_distance > c.max_slip
            terminated[w] = any_terminated(self.termination_terms, self._point(w, r))
        reward, terms = self._term_loop(live, lambda w: self._point(w, per_world[w]))
        truncated = live & ~terminated & (self._steps >= self.max_episode_steps)
        info = self._metrics()
        ws = self._worlds
        info.update({"reward_terms": terms,
                     "pull_force_N": np.array([wd.pull for wd in ws]),
                     "normal_force_N": np.array([wd.normal_total for wd in ws]),
                     "least_squeeze_N": np.array([least_squeeze(wd.pull, wd.mu) for wd in ws]),
                     "dropped": np.array([wd.lost for wd in ws]) & live})
        ok = truncated & np.array([wd.slip_distance <= c.slip_tolerance for wd in ws])
        info["success"], info["is_success"] = ok.copy(), ok.copy()
        return np.where(live, reward, 0.0), terminated, truncated, info

    def _point(self, w: int, readings: tuple):
        wd = self._worlds[w]
        return self._view.point(readings, slip_distance=wd.slip_distance, slip_before=wd.slip_before,
                                normal_total=wd.normal_total, pull=wd.pull, mu=wd.mu, lost=wd.lost,
                                steps=int(self._steps[w]))

    def _metrics(self) -> dict:
        c, ws = self.config, self._worlds
        mu = np.array([wd.mu for wd in ws])
        return {"mu": mu, "mu_static": c.static_friction_ratio * mu,
                "young_scale": np.array([wd.young_scale for wd in ws]),
                "slip_distance_m": np.array([wd.slip_distance for wd in ws]),
                "peak_force_N": np.array([wd.peak_force for wd in ws])}

    def _device_info(self, out: dict) -> dict:
        return {"pull_force_N": out["pull_force"], "normal_force_N": out["normal_force"],
                "least_squeeze_N": out["least_squeeze"], "dropped": out["dropped"], "success": out["success"],
                "is_success": out["success"]}

    def _observe(self):
        if self._device_terms is not None:
            obs, metrics = self._device_terms.observe()
            self._device_metrics = metrics
            return obs
        pos, fn, ft, rep, opening = self._read()
        obs, ws = self._obs, self._worlds
        obs[:, 0] = opening
        obs[:, 1:4] = fn
        obs[:, 4:7] = ft
        obs[:, 7] = rep["slipping"]
        obs[:, 8] = rep["contacts"]
        obs[:, 9] = [wd.pull for wd in ws]
        obs[:, 10] = [float((pos[w] - wd.pos0) @ self.pull_dir) for w, wd in enumerate(ws)]
        obs[:, 11] = [wd.slip_distance for wd in ws]
        return obs.copy()
