"""Grasp-v0's per-step task bookkeeping for W worlds kept on the Warp device
(:class:`GraspDeviceTerms`), the state behind ``BatchedGraspEnv(..., device_outputs=True)``.

The per-world state (target, initial and best distance, last distance, grasp history, the slip
tracker's nodes, wrist and centroid at its start, slip distance, peak force, step count, friction
and Young's scale) lives in Warp arrays on the env's device; the kernels of
:mod:`surgsim_envs.batch.grasp_kernels` update it one thread per world, reading the physics arrays
in place (:meth:`BatchSimulation.arrays`, the per-geom sums of :meth:`BatchSimulation.geom_sum_arrays`
and the contacted-node mask of :meth:`BatchSimulation.contact_node_mask`). Every :meth:`evaluate`
and :meth:`observe` writes fresh output arrays: what a step returned is never written again, so a
caller may keep it (a rollout buffer) while it shares the memory through DLPack.

Per step the host sends the live and unstable masks (W,) and reads back the ended flags (W,),
which the autoreset needs (a reset draws friction, Young's scale and target from each world's
numpy generator, as the single env does).
"""

from __future__ import annotations

import math

import numpy as np

from surgsim_envs.batch.backend import require
from surgsim_envs.batch.device_terms import GraspSceneDeviceTerms
from surgsim_envs.errors import ConfigError

#: Grasp-v0's declared reward terms (name, weight field), in the order the kernel sums them
DEVICE_TERMS = (("excess_force", "force_weight"), ("contact", "contact_weight"), ("progress", "progress_weight"),
                ("slip", "slip_weight"), ("drop", "drop_penalty"), ("success", "success_bonus"))


class GraspDeviceTerms(GraspSceneDeviceTerms):
    """The device state and kernels of ``sim.W`` Grasp-v0 episodes (module docstring).

    sim: the env's :class:`BatchSimulation`; config: its :class:`GraspConfig`; reward_terms: the
    env's declared terms (``RewardManager.terms``: checked against :data:`DEVICE_TERMS`); tool: the
    template's grasper (its body, jaw geoms, jaw joint and opening); tool_name: its name in the
    scene; max_episode_steps: the truncation step.
    """

    OBS_WIDTH = 15

    def __init__(self, sim, config, reward_terms, tool, tool_name: str, max_episode_steps: int):
        wp, _ = require()
        from surgsim_envs.batch import device_reductions as R
        from surgsim_envs.batch import grasp_kernels as K

        declared = tuple((t.name, t.weight) for t in reward_terms)
        if declared != DEVICE_TERMS:
            raise ConfigError(f"device_outputs=True computes Grasp-v0's reward terms {list(DEVICE_TERMS)} in Warp "
                              f"kernels (batch/grasp_kernels.py), but the env declares {list(declared)}; add the new "
                              "term to evaluate_step, or leave device_outputs out (the numpy path runs the declared "
                              "terms)")
        jaws = sim.geom_columns(tool.jaw_geom_ids)
        if len(jaws) != K.JAWS:
            raise ConfigError(f"device_outputs=True computes the per-jaw terms of a {K.JAWS}-jaw grasper, but tool "
                              f"{tool_name!r} has {len(jaws)} jaws; leave device_outputs out for this scene")
        self.wp, self.K = wp, K
        self.sim, self.device = sim, sim.device
        self.W = W = sim.W
        dev = self.device
        self.body = int(sim.tool_body[tool_name])
        self.jaw_qpos = int(tool.jaw_qpos_adr[0])
        self.jaw_columns = wp.array(np.asarray(jaws, dtype=np.int32), dtype=wp.int32, device=dev)
        self.tool_rows = wp.array(np.asarray(sim.tool_index[tool_name], dtype=np.int32), dtype=wp.int32, device=dev)
        c = config
        p = K.GraspParams()
        p.hold_force = float(c.hold_force)
        p.damage_force = float(c.damage_force)
        p.tolerance = float(c.tolerance)
        p.max_episode_steps = int(max_episode_steps)
        p.open_radius = float(tool.config.open_radius)
        p.static_friction_ratio = float(c.static_friction_ratio)
        p.compensated_sum = int(R.PYTHON_SUM_COMPENSATED)
        for (name, field), attr in zip(DEVICE_TERMS, ("w_excess_force", "w_contact", "w_progress", "w_slip", "w_drop",
                                                      "w_success")):
            setattr(p, attr, float(getattr(c, field)))
        self.params = p
        N = sim.topology.n_nodes
        s = K.GraspState()
        z = lambda shape, dtype: wp.zeros(shape, dtype=dtype, device=dev)  # noqa: E731
        s.goal, s.tool0, s.centroid0 = z(W, wp.vec3d), z(W, wp.vec3d), z(W, wp.vec3d)
        s.goal_dist0, s.best_dist, s.slip_distance, s.peak, s.mu, s.young_scale = (z(W, wp.float64) for _ in range(6))
        s.distance = wp.full(W, math.nan, dtype=wp.float64, device=dev)     # no step taken yet
        s.was_grasped, s.slip_active, s.slip_count, s.steps = (z(W, wp.int32) for _ in range(4))
        s.slip_nodes = z((W, N), wp.int32)
        self.state = s

    def reset(self, worlds: np.ndarray, goals: np.ndarray, goal_dist0: np.ndarray, mu: np.ndarray,
              young_scale: np.ndarray) -> None:
        """A new episode in ``worlds`` with targets ``goals`` (k, 3) m, initial distances (k,) m,
        friction and Young's scale (k,) each: the host's draws."""
        worlds = np.asarray(worlds, dtype=np.int32).reshape(-1)
        if not len(worlds):
            return
        wp = self.wp
        self.wp.launch(self.K.reset_worlds, dim=len(worlds), device=self.device,
                       inputs=[self.state, self._host(worlds, np.int32),
                               wp.array(np.ascontiguousarray(goals, dtype=np.float64).reshape(-1, 3), dtype=wp.vec3d,
                                        device=self.device),
                               self._host(goal_dist0, np.float64), self._host(mu, np.float64),
                               self._host(young_scale, np.float64)])

    def evaluate(self, live: np.ndarray, unstable: np.ndarray) -> tuple[dict, np.ndarray]:
        """The step's evaluation after the physics: ``({name: fresh device array}, ended (W,) bool on
        the host)``; names: reward, terms (6, W), terminated, truncated, grasped, success, dropped,
        distance. ``live``: the worlds that stepped their episode; ``unstable``: worlds that
        diverged and were reset this step (terminated)."""
        wp, W, sim = self.wp, self.W, self.sim
        arrays = sim.arrays()
        geom_fn, _ = sim.geom_sum_arrays()
        mask = sim.contact_node_mask()
        e = lambda dtype, shape=W: wp.empty(shape, dtype=dtype, device=self.device)  # noqa: E731
        out = {"reward": e(wp.float64), "terms": e(wp.float64, (len(DEVICE_TERMS), W)), "terminated": e(wp.bool),
               "truncated": e(wp.bool), "ended": e(wp.bool), "grasped": e(wp.bool), "success": e(wp.bool),
               "dropped": e(wp.bool), "distance": e(wp.float64)}
        wp.launch(self.K.evaluate_step, dim=W, device=self.device,
                  inputs=[self.state, self.params, arrays["xpos"], self.body, geom_fn, self.jaw_columns,
                          arrays["tool_contacts"], arrays["tool_slipping"], self.tool_rows, mask,
                          arrays["tissue_positions"], self._host(live, np.int32), self._host(unstable, np.int32)],
                  outputs=[out[k] for k in ("reward", "terms", "terminated", "truncated", "ended", "grasped",
                                            "success", "dropped", "distance")])
        return out, out["ended"].numpy().copy()
