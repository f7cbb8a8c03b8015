"""Grasp-v0 as a Gymnasium vector env over W batched worlds (:class:`BatchedGraspEnv`, on
:class:`~surgsim_envs.batch.env.BatchedTaskEnv`).

``gym.make_vec("SurgSim/Grasp-v0", num_envs=W, vectorization_mode="vector_entry_point",
device="cpu")`` returns it (``device="cuda"`` where a GPU exists). Every world is one Grasp-v0
episode (:mod:`surgsim_envs.envs.grasp`) with the single env's observation (15 entries, same
names, order and bounds), reward and termination terms (``GraspEnv.REWARD_TERMS`` /
``TERMINATION_TERMS``, run per world on a :class:`~surgsim_envs.batch.world_view.WorldView`) and
info metrics:

* the physics readouts of all worlds come from :class:`~surgsim_envs.batch.simulation.BatchSimulation`
  (wrist position, per-jaw normal and tangential forces, contact report, jaw opening, the
  contacted nodes a grasp's slip tracker starts from);
* the grasp bookkeeping of the single env's ``_update`` (grasp, slip tracker, record progress,
  success, drop) runs per live world on the host, with the same term functions
  (:mod:`surgsim_envs.envs.grasp.terms`).

Per-world randomisation as the single env's ``reset``: friction coefficient (kinetic; static =
``static_friction_ratio`` times it, :meth:`BatchSimulation.set_tool_friction`), Young's modulus scale
(:meth:`BatchSimulation.set_young_factors`) and the target offsets, drawn in the single env's order
from each world's generator. The ``organ`` option changes the mesh, and a batch holds one mesh, so it
is refused at reset; choose the organ in the config (``organ=...`` at construction).

``device_outputs=True`` (``gym.make_vec(..., device="cpu", device_outputs=True)``) moves the
per-step bookkeeping (grasp, slip tracker, progress record, success, drop), observation and reward
terms onto the Warp device: the kernels of :mod:`surgsim_envs.batch.grasp_kernels` on the state
of :class:`~surgsim_envs.batch.grasp_device_terms.GraspDeviceTerms`, one thread per world, the same
arithmetic as the numpy path. ``step`` and ``reset`` then return observations (W, 15) float32,
rewards (W,) float64, terminated and truncated (W,) bool as fresh Warp arrays on the device, and
the info entries (``reward_terms``, ``steps``, ``grasped``, ``distance_to_target_m``,
``success`` / ``is_success``, ``dropped``, ``mu``, ``mu_static``, ``young_scale``,
``slip_distance_m``, ``peak_force_N``) as device arrays too; ``info["unstable"]`` (a diverged
world, found on the host) stays numpy.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from surgsim_envs.batch.env import BatchedTaskEnv
from surgsim_envs.batch.grasp_device_terms import GraspDeviceTerms
from surgsim_envs.envs.checks import sample
from surgsim_envs.envs.grasp import GraspEnv
from surgsim_envs.envs.grasp.terms import SlipTracker, is_grasped, record_progress, total_normal_force
from surgsim_envs.envs.terms.action import jaw_opening
from surgsim_envs.envs.terms.force import vector_norm
from surgsim_envs.envs.terms.termination import any_terminated


class _GraspWorld:
    """One world's episode state under the single env's attribute names (GraspEnv / GraspSceneEnv)."""

    def __init__(self):
        self.slip = SlipTracker()

    def start(self, goal: np.ndarray, home: np.ndarray, mu: float, young_scale: float) -> None:
        self.goal = goal
        self.prev_dist = float(np.linalg.norm(goal - home))
        self.goal_dist0 = max(self.prev_dist, 1e-6)
        self.best_dist = self.goal_dist0
        self.mu, self.young_scale = mu, young_scale
        self.slip.reset()
        self.slip_distance = 0.0
        self.was_grasped = self.grasped = self.succeeded = self.dropped = False
        self.progress_gain = 0.0
        self.peak_force = 0.0


class BatchedGraspEnv(BatchedTaskEnv):
    """Grasp-v0 in ``num_envs`` batched worlds on Warp device ``device`` (module docstring).

    num_envs: worlds W; device: "cpu" or "cuda"; config / overrides: as for
    ``gym.make("SurgSim/Grasp-v0", ...)`` (a :class:`GraspConfig` and field overrides).
    """

    TEMPLATE = GraspEnv
    DEVICE_OUTPUTS = True
    REFUSED = {"organ": "it changes the tissue mesh and a batch holds one mesh for all worlds; build the batched "
                        "env with the organ in its config (gym.make_vec(..., organ=...)) instead"}

    def __init__(self, num_envs: int = 1, *, device: str = "cpu", config=None, max_episode_steps: int | None = None,
                 device_outputs: bool = False, **overrides):
        super().__init__(num_envs, device=device, config=config, max_episode_steps=max_episode_steps,
                         device_outputs=device_outputs, **overrides)
        t = self.template
        self.tool_name = t.tool_name
        self.home = np.array(t.home, dtype=np.float64)
        self.frame = np.array(t.frame, dtype=np.float64)
        self.gcfg = t.gcfg
        self.pull_dir = np.array(t.pull_dir, dtype=np.float64)
        self.jaw_actuator = int(t.tool.jaw_actuator_id)
        W = self.num_envs
        self._worlds = [_GraspWorld() for _ in range(W)]
        self._target = np.tile(self.home, (W, 1))
        self._mask = None
        self._device_terms = (GraspDeviceTerms(self.sim, self.config, self.rewards.terms, t.tool, self.tool_name,
                                               self.max_episode_steps) if self.device_outputs else None)
        self._device_metrics = None

    # -- episodes ---------------------------------------------------------------------------------
    def _reset_worlds(self, idx: np.ndarray, options: dict[str, Any]) -> None:
        """Randomise and reset worlds ``idx`` as the single env's reset does (same draws, same order)."""
        c = self.config
        sim = self.sim
        mu, scale = np.zeros(len(idx)), np.zeros(len(idx))
        for k, w in enumerate(idx):
            rng = self._rngs[w]
            mu[k] = sample(rng, options.get("mu", c.mu), "mu", 0.0, 2.0)
            scale[k] = sample(rng, options.get("young_scale", c.young_scale), "young_scale", 0.5, 1.25)
            rng.integers(2**31)             # the single env's physics seed draw: keeps the streams aligned
            ox = sample(rng, options.get("target_offset_x", c.target_offset_x), "target_offset_x", -c.workspace,
                        c.workspace)
            oz = sample(rng, options.get("target_offset_z", c.target_offset_z), "target_offset_z", -c.workspace,
                        c.workspace)
            goal = self.home + self.pull_dir * ox + np.array([0.0, 0.0, oz])
            self._worlds[w].start(goal, self.home, float(mu[k]), float(scale[k]))
        sim.reset_worlds(idx)
        sim.set_tool_friction(mu, c.static_friction_ratio * mu, worlds=idx)
        sim.set_young_factors(np.repeat(scale[:, None], sim.material_tets, axis=1), worlds=idx)
        self._target[idx] = self.home
        self._steps[idx] = 0
        self._readings = None
        if self._device_terms is not None:
            ws = [self._worlds[w] for w in idx]
            self._device_terms.reset(idx, np.array([wd.goal for wd in ws]), np.array([wd.goal_dist0 for wd in ws]),
                                     mu, scale)

    def _reset_info(self, idx) -> dict:
        if self._device_terms is not None:
            return {k: v for k, v in self._device_metrics.items() if k != "steps"}
        return self._metrics()

    # -- stepping ---------------------------------------------------------------------------------
    def _apply_actions(self, a: np.ndarray, live: np.ndarray) -> None:
        """Wrist targets and jaw goals as the single env's ``_apply_action`` (``wrist_target``,
        ``jaw_opening``), for the live worlds."""
        c, g = self.config, self.gcfg
        idx = np.flatnonzero(live)
        pos = self._target[idx] + a[idx, :3] * c.max_step
        local = np.clip((pos - self.home) @ self.frame, -c.workspace, c.workspace)   # frame.T @ (pos - home)
        self._target[idx] = self.home + local @ self.frame.T
        self.sim.set_tool_targets(self.tool_name, self._target[idx], worlds=idx)
        opening = np.array([jaw_opening(float(v), g.open_radius, g.min_radius) for v in a[idx, 3]])
        self.sim.set_actuator_goals([self.jaw_actuator], (g.open_radius - opening)[:, None], worlds=idx)

    def _read(self):
        """(wrist (W, 3) m, jaw normal (W, 3) N, jaw tangential (W, 3) N, contact report {key: (W,)},
        jaw opening (W,) m) of the current physics state."""
        if self._readings is None:
            sim, name = self.sim, self.tool_name
            jaws = sim.jaw_forces(name)
            self._readings = (sim.tool_positions(name), jaws["normal"], jaws["tangential"],
                              sim.tool_contact_report(name), sim.jaw_openings(name))
            self._mask = None
        return self._readings

    def _world_readings(self, w: int) -> tuple:
        """World ``w``'s readings as the single env's ``readings()``: (wrist, normal, tangential, report)."""
        pos, fn, ft, rep, _ = self._read()
        return pos[w], fn[w], ft[w], {k: (int(v[w]) if k in ("contacts", "slipping") else float(v[w]))
                                      for k, v in rep.items()}

    def _update_world(self, w: int, readings: tuple, positions) -> None:
        """The single env's ``_update`` / ``_update_grasp`` for world ``w`` (grasp, slip, progress
        record, success, drop); ``positions()`` gives the (W, N, 3) node positions, read once a step."""
        c, world = self.config, self._worlds[w]
        pos, fn, _, rep = readings
        grasped = is_grasped(fn, c.hold_force)
        if grasped and not world.slip.active:
            if self._mask is None:
                self._mask = self.sim.contact_node_mask().numpy()
            nodes = np.flatnonzero(self._mask[w])
            if len(nodes):
                world.slip.start(pos, positions()[w], nodes)
        world.slip_distance = world.slip.distance(pos, positions()[w]) if world.slip.active else 0.0
        total = total_normal_force(fn)
        if total > world.peak_force:
            world.peak_force = total
        world.grasped = grasped
        dist = vector_norm(world.goal - pos)
        world.distance = dist
        world.progress_gain = 0.0
        world.succeeded = world.dropped = False
        if grasped:
            world.progress_gain, world.best_dist = record_progress(world.best_dist, dist)
            world.was_grasped = True
            if dist <= c.tolerance:
                world.succeeded = True
        elif world.was_grasped and rep["contacts"] == 0:
            world.dropped = True
        world.prev_dist = dist

    def _evaluate(self, a: np.ndarray, live: np.ndarray):
        W = self.num_envs
        cache = {}

        def positions():
            if "x" not in cache:
                cache["x"] = self.sim.tissue_positions()
            return cache["x"]

        per_world = {}
        terminated = np.zeros(W, dtype=bool)
        for w in np.flatnonzero(live):
            r = per_world[w] = self._world_readings(w)
            self._update_world(w, r, positions)
            terminated[w] = any_terminated(self.termination_terms, self._point(w, r))
        reward, terms = self._term_loop(live, lambda w: self._point(w, per_world[w]))
        truncated = live & ~terminated & (self._steps >= self.max_episode_steps)
        info = self._metrics()
        info.update({"reward_terms": terms, "steps": self._steps.copy(),
                     "grasped": np.array([wd.grasped for wd in self._worlds]) & live,
                     "distance_to_target_m": np.array([getattr(wd, "distance", np.nan) for wd in self._worlds])})
        for key in ("success", "is_success"):
            info[key] = np.array([wd.succeeded for wd in self._worlds]) & live
        info["dropped"] = np.array([wd.dropped for wd in self._worlds]) & live
        return np.where(live, reward, 0.0), terminated, truncated, info

    def _point(self, w: int, readings: tuple):
        wd = self._worlds[w]
        return self._view.point(readings, grasped=wd.grasped, progress_gain=wd.progress_gain,
                                goal_dist0=wd.goal_dist0, succeeded=wd.succeeded, dropped=wd.dropped,
                                steps=int(self._steps[w]))

    def _metrics(self) -> dict:
        c, ws = self.config, self._worlds
        mu = np.array([wd.mu for wd in ws])
        return {"mu": mu, "mu_static": c.static_friction_ratio * mu,
                "young_scale": np.array([wd.young_scale for wd in ws]),
                "slip_distance_m": np.array([wd.slip_distance for wd in ws]),
                "peak_force_N": np.array([wd.peak_force for wd in ws])}

    def _device_info(self, out: dict) -> dict:
        return {"grasped": out["grasped"], "distance_to_target_m": out["distance"], "success": out["success"],
                "is_success": out["success"], "dropped": out["dropped"]}

    def _observe(self):
        if self._device_terms is not None:
            obs, metrics = self._device_terms.observe()
            self._device_metrics = metrics
            return obs
        pos, fn, ft, rep, opening = self._read()
        obs = self._obs
        obs[:, 0:3] = pos
        obs[:, 3:6] = np.array([wd.goal for wd in self._worlds]) - pos
        obs[:, 6] = opening
        obs[:, 7:10] = fn
        obs[:, 10:13] = ft
        obs[:, 13] = rep["slipping"]
        obs[:, 14] = rep["contacts"]
        return obs.copy()
