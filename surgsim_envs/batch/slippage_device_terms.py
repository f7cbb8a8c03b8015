"""Slippage-v0's control schedule and per-step task bookkeeping for W worlds kept on the Warp device
(:class:`SlippageDeviceTerms`), the state behind ``BatchedSlippageEnv(..., device_outputs=True)``.

The per-world state (pull parameters, the float64 clock and the pull's start time, the wrist and
the slip tracker's nodes and centroid at the grasp, pull, slip distance and its previous value,
summed squeeze and its peak, loss flag, step count, friction and Young's scale) lives in Warp
arrays on the env's device; the kernels of :mod:`surgsim_envs.batch.slippage_kernels` update it
one thread per world, reading the physics arrays in place (:meth:`BatchSimulation.arrays`, the
float64 controls, the per-geom sums of :meth:`BatchSimulation.geom_sum_arrays` and the
contacted-node mask of :meth:`BatchSimulation.contact_node_mask`). :meth:`schedule` fills the
control step's (K, W, 2) jaw and pull schedule on the device, which
:meth:`BatchSimulation.step_with_control_array` steps without a host copy. Every :meth:`evaluate`
and :meth:`observe` writes fresh output arrays: what a step returned is never written again, so a
caller may keep it (a rollout buffer) while it shares the memory through DLPack.

Per step the host sends the actions and the live mask (2 x W numbers) for the schedule, the live
and unstable masks for the evaluation, and reads back the ended flags (W,), which the autoreset
needs. A reset stays on the host: the draws come from each world's numpy generator and the settle
runs the host schedule (as the numpy path); :meth:`reset` then starts the episode on the device.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.batch.backend import require
from surgsim_envs.batch.device_terms import GraspSceneDeviceTerms
from surgsim_envs.errors import ConfigError

#: Slippage-v0's declared reward terms (name, weight field), in the order the kernel sums them
DEVICE_TERMS = (("slip", "slip_weight"), ("excess_squeeze", "squeeze_weight"), ("hold", "hold_reward"),
                ("drop", "drop_penalty"))


class SlippageDeviceTerms(GraspSceneDeviceTerms):
    """The device state and kernels of ``sim.W`` Slippage-v0 episodes (module docstring).

    sim: the env's :class:`BatchSimulation`; config: its :class:`SlippageConfig`; reward_terms: the
    env's declared terms (``RewardManager.terms``: checked against :data:`DEVICE_TERMS`); tool: the
    template's grasper; tool_name: its name in the scene; actuators: (jaw, pull) actuator ids;
    pull_dir: the pull's unit direction; h: s, one MuJoCo step; max_episode_steps: the truncation step.
    """

    OBS_WIDTH = 12

    def __init__(self, sim, config, reward_terms, tool, tool_name: str, actuators, pull_dir, h: float,
                 max_episode_steps: int):
        wp, _ = require()
        from surgsim_envs.batch import device_reductions as R
        from surgsim_envs.batch import slippage_kernels as K

        declared = tuple((t.name, t.weight) for t in reward_terms)
        if declared != DEVICE_TERMS:
            raise ConfigError(f"device_outputs=True computes Slippage-v0's reward terms {list(DEVICE_TERMS)} in Warp "
                              f"kernels (batch/slippage_kernels.py), but the env declares {list(declared)}; add the "
                              "new term to evaluate_step, or leave device_outputs out (the numpy path runs the "
                              "declared terms)")
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
        self.actuators = [int(a) for a in actuators]
        self.jaw_columns = wp.array(np.asarray(jaws, dtype=np.int32), dtype=wp.int32, device=dev)
        self.tool_rows = wp.array(np.asarray(sim.tool_index[tool_name], dtype=np.int32), dtype=wp.int32, device=dev)
        c, g = config, tool.config
        p = K.SlippageParams()
        p.open_radius = float(g.open_radius)
        p.min_radius = float(g.min_radius)
        p.closing_step = float(c.closing_speed * h)          # as the host schedule's lim
        p.h = float(h)
        p.max_pull = float(c.max_pull)
        p.max_slip = float(c.max_slip)
        p.slip_tolerance = float(c.slip_tolerance)
        p.static_friction_ratio = float(c.static_friction_ratio)
        p.max_episode_steps = int(max_episode_steps)
        p.jaw_act, p.pull_act = self.actuators
        p.pull_dir = wp.vec3d(*(float(v) for v in np.asarray(pull_dir, dtype=np.float64).reshape(3)))
        p.compensated_sum = int(R.PYTHON_SUM_COMPENSATED)
        for (_, field), attr in zip(DEVICE_TERMS, ("w_slip", "w_squeeze", "w_hold", "w_drop")):
            setattr(p, attr, float(getattr(c, field)))
        self.params = p
        N = sim.topology.n_nodes
        s = K.SlippageState()
        z = lambda shape, dtype: wp.zeros(shape, dtype=dtype, device=dev)  # noqa: E731
        (s.rate, s.amplitude, s.frequency, s.phase, s.t0, s.clock, s.pull, s.slip_distance, s.slip_before,
         s.normal_total, s.peak, s.mu, s.young_scale) = (z(W, wp.float64) for _ in range(13))
        s.pos0, s.centroid0 = z(W, wp.vec3d), z(W, wp.vec3d)
        s.slip_count, s.lost, s.steps = (z(W, wp.int32) for _ in range(3))
        s.slip_nodes = z((W, N), wp.int32)
        self.state = s
        self._values = None                # the (K, W, 2) schedule, rewritten every control step

    def reset(self, worlds: np.ndarray, clock: np.ndarray, mu: np.ndarray, young_scale: np.ndarray,
              rate: np.ndarray, amplitude: np.ndarray, frequency: np.ndarray, phase: np.ndarray) -> np.ndarray:
        """A new episode in ``worlds`` after their settle: the host's draws and clocks, (k,) each;
        the slip tracker starts on each world's contacted nodes. Returns their counts (k,) on the
        host (0: the jaws closed on nothing)."""
        worlds = np.asarray(worlds, dtype=np.int32).reshape(-1)
        if not len(worlds):
            return np.zeros(0, dtype=np.int32)
        wp, sim = self.wp, self.sim
        mask = sim.contact_node_mask()
        arrays = sim.arrays()
        count = wp.empty(len(worlds), dtype=wp.int32, device=self.device)
        f64 = lambda v: self._host(v, np.float64)  # noqa: E731
        wp.launch(self.K.reset_worlds, dim=len(worlds), device=self.device,
                  inputs=[self.state, self._host(worlds, np.int32), f64(rate), f64(amplitude), f64(frequency),
                          f64(phase), f64(mu), f64(young_scale), f64(clock), arrays["xpos"], self.body, mask,
                          arrays["tissue_positions"], count])
        return count.numpy().copy()

    def schedule(self, steps: int, actions: np.ndarray, live: np.ndarray):
        """The control step's schedule: a (steps, W, 2) float64 device array (jaw, pull controls per
        MuJoCo step) from ``actions`` (W,) closure values of the ``live`` worlds (the others hold
        their controls); the clocks advance ``steps`` MuJoCo steps. The array is rewritten by the
        next call."""
        wp = self.wp
        if self._values is None or self._values.shape[0] != steps:
            self._values = wp.empty((steps, self.W, 2), dtype=wp.float64, device=self.device)
        wp.launch(self.K.control_schedule, dim=self.W, device=self.device,
                  inputs=[self.state, self.params, self.sim.controls_array(), self._host(actions, np.float64),
                          self._host(live, np.int32), self._values])
        return self._values

    def evaluate(self, live: np.ndarray, unstable: np.ndarray) -> tuple[dict, np.ndarray]:
        """The step's evaluation after the physics: ``({name: fresh device array}, ended (W,) bool on
        the host)``; names: reward, terms (4, W), terminated, truncated, success, dropped, pull_force,
        normal_force, least_squeeze. ``live``: the worlds that stepped their episode; ``unstable``:
        worlds that diverged and were reset this step (terminated)."""
        wp, W, sim = self.wp, self.W, self.sim
        arrays = sim.arrays()
        geom_fn, _ = sim.geom_sum_arrays()
        e = lambda dtype, shape=W: wp.empty(shape, dtype=dtype, device=self.device)  # noqa: E731
        keys = ("reward", "terms", "terminated", "truncated", "ended", "success", "dropped", "pull_force",
                "normal_force", "least_squeeze")
        out = {"reward": e(wp.float64), "terms": e(wp.float64, (len(DEVICE_TERMS), W)), "terminated": e(wp.bool),
               "truncated": e(wp.bool), "ended": e(wp.bool), "success": e(wp.bool), "dropped": e(wp.bool),
               "pull_force": e(wp.float64), "normal_force": e(wp.float64), "least_squeeze": e(wp.float64)}
        wp.launch(self.K.evaluate_step, dim=W, device=self.device,
                  inputs=[self.state, self.params, arrays["xpos"], self.body, geom_fn, self.jaw_columns,
                          arrays["tool_contacts"], self.tool_rows, arrays["tissue_positions"],
                          self._host(live, np.int32), self._host(unstable, np.int32)],
                  outputs=[out[k] for k in keys])
        return out, out["ended"].numpy().copy()
