"""SurgSim/Slippage-v0: hold a grasped organ against a ramping, varying pull with the least squeeze.

At reset the three-jaw grasper closes on the organ tip (``initial_closure``, ``settle_time`` s).
Then the wrist is pulled out of the organ along the tool axis by a force
``F(t) = rate * t + amplitude * sin(2 pi f t + phase)`` (N, >= 0; the along-axis wrist drive
becomes a force motor with ``pull_damping`` N s/m of joint damping), while the tool-tissue
friction mu is drawn per episode (0.3-1.0; kinetic, with a static coefficient
``static_friction_ratio * mu``, default ratio 1). The agent only modulates the jaw closure.

Action (1,) in [-1, 1]: jaw opening target from fully open (-1) to ``min_radius`` (+1),
rate-limited at ``closing_speed`` m/s.

Observation (12,) float32, SI: jaw opening (1) m; per-jaw normal force (3) N; per-jaw tangential
force (3) N; slipping contact nodes (1); contact nodes (1); pull force (1) N; wrist displacement
along the pull since the grasp (1) m; slip distance (1) m (tissue relative to the jaws).

Reward per step: ``hold_reward`` while the grasp holds, ``- slip_weight * (slip increase in mm)+ - squeeze_weight * (sum normal -
|F| / mu)+`` (the squeeze above the least one that holds); ``- drop_penalty`` and termination
on loss of grasp (no contact node, or slip beyond ``max_slip``). ``info["success"]``: the time
limit reached with slip below ``slip_tolerance``.

Actuation note: this task writes the jaw and pull actuator controls (``MjData.ctrl``) itself
each physics step (it never calls ``set_jaw_opening``/``set_tool_target``, whose rate limiter
would overwrite them).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces

from surgsim_envs.envs.checks import sample
from surgsim_envs.envs.grasp.scene import GraspSceneEnv
from surgsim_envs.envs.grasp.terms import contact_nodes
from surgsim_envs.envs.slippage.config import SlippageConfig
from surgsim_envs.envs.slippage.terms import (REWARD_TERMS, TERMINATION_TERMS, control_schedule, least_squeeze,
                                             no_pull, pull_force)
from surgsim_envs.envs.terms import ObsTerm
from surgsim_envs.envs.terms.action import ActionTerm, jaw_closure
from surgsim_envs.errors import ConfigError
from surgsim_envs.scene.approach_snapshot import ApproachSnapshot


class SlippageEnv(GraspSceneEnv):
    """Slippage-v0 (see module docstring)."""

    config_cls = SlippageConfig
    TASK_ID = "SurgSim/Slippage-v0"
    OPTIONS = ("organ", "mu", "young_scale", "pull_rate", "pull_amplitude", "pull_frequency")
    ACTION = ActionTerm("grasper", 1, "[close]: jaw closure (the wrist is pulled by the task's motor)")
    REWARD_TERMS = REWARD_TERMS
    TERMINATION_TERMS = TERMINATION_TERMS

    def _build(self) -> None:
        self._approach = ApproachSnapshot()
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self._build_scene()
        self._set_observation_terms(self._observation_terms())

    def _observation_terms(self) -> list:
        _, _, span = self._reach()
        return [ObsTerm("jaw_opening", "m", 1, 0.0, 2.0 * float(self.gcfg.open_radius)),
                ObsTerm("jaw_normal_force", "N", 3, 0.0), ObsTerm("jaw_tangential_force", "N", 3, 0.0),
                ObsTerm("slipping_contacts", "1", 1, 0.0), ObsTerm("contacts", "1", 1, 0.0),
                ObsTerm("pull_force", "N", 1, 0.0, float(self.config.max_pull)),
                ObsTerm("wrist_displacement_along_pull", "m", 1, -span, span),
                ObsTerm("slip_distance", "m", 1, 0.0)]

    def _select_tool(self) -> None:
        super()._select_tool()
        self._pull_act = int(self.tool.actuator_ids[2])      # slide along the tool axis: + is out of the organ
        self._jaw_act = int(self.tool.jaw_actuator_id)

    def _on_new_simulation(self, sim) -> None:
        """The along-axis wrist drive becomes a force motor (the pull) with joint damping."""
        m = sim.model
        a, dof = self._pull_act, int(self.tool.dof_adr[2])
        m.actuator_gainprm[a, :] = 0.0
        m.actuator_gainprm[a, 0] = 1.0
        m.actuator_biasprm[a, :] = 0.0
        m.actuator_ctrlrange[a] = [-self.config.max_pull, self.config.max_pull]
        m.dof_damping[dof] = self.config.pull_damping

    def _closure_ctrl(self, action_value: float) -> float:
        """Jaw actuator target (closing travel, m) of a closure action in [-1, 1]."""
        return jaw_closure(action_value, self.gcfg.open_radius, self.gcfg.min_radius)

    def _run(self, steps: int, jaw_goal: float, pull: callable) -> None:
        """``steps`` physics steps; before each, the jaw control moves towards ``jaw_goal`` by at most
        ``closing_speed * dt`` and the pull motor gets ``pull(t)`` (t the simulation time before the
        step; ``pull`` None: the episode's pull, :meth:`_pull_at`). Both schedules are computed ahead
        (:func:`control_schedule`) and run in one :meth:`Simulation.step_with_controls`."""
        sim = self.sim
        n = sim.tissue_subcycles          # controls change once per MuJoCo step of n physics steps
        dt = sim.dt * n
        steps = -(-steps // n)
        lim = self.config.closing_speed * dt
        values = np.empty((steps, 2))
        jaw = float(sim.data.ctrl[self._jaw_act])
        t = float(sim.data.time)
        if pull is None:            # the episode's pull: schedule and pull in one compiled call
            control_schedule(values, jaw, jaw_goal, lim, t, dt, True, self.rate, self.amplitude, self.frequency, self.phase,
                      self.t0, float(self.config.max_pull))
            if steps:
                self.pull = float(values[-1, 1])
        else:
            control_schedule(values, jaw, jaw_goal, lim, t, dt, False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            t_k = t
            for k in range(steps):
                values[k, 1] = pull(t_k)
                t_k += dt
        sim.step_with_controls([self._jaw_act, self._pull_act], values)

    def _randomise(self, options: dict[str, Any]) -> None:
        c, rng = self.config, self.np_random
        self._randomise_common(options)
        self.rate = sample(rng, options.get("pull_rate", c.pull_rate), "pull_rate", 0.0, 10.0)
        self.amplitude = sample(rng, options.get("pull_amplitude", c.pull_amplitude), "pull_amplitude", 0.0, 10.0)
        self.frequency = sample(rng, options.get("pull_frequency", c.pull_frequency), "pull_frequency", 0.0, 50.0)
        self.phase = float(rng.uniform(0.0, 2.0 * math.pi))
        self._settle(int(round(c.settle_time / self.sim.dt)), self._closure_ctrl(c.initial_closure))
        pos = self.sim.tool_position(self.tool_name)
        nodes = contact_nodes(self.sim)
        if len(nodes) == 0:
            raise ConfigError("Slippage: the jaws closed on nothing during the settle; raise initial_closure")
        self.slip.start(pos, self.sim.tissue().positions, nodes)
        self.t0 = self.sim.time
        self.pos0 = pos
        self.jaw_goal = self._closure_ctrl(c.initial_closure)
        self.pull = 0.0

    def _settle(self, steps: int, goal: float) -> None:
        """The reset's grasp: ``steps`` physics steps closing the jaws towards ``goal`` with no pull.
        With ``replay_approach`` the contact-free first part (the jaws travelling through air) is
        restored from a snapshot (:mod:`surgsim_envs.scene.approach_snapshot`), not simulated."""
        def run(n: int) -> None:
            self._run(n, goal, no_pull)

        done = self._approach.skip(self.sim, ("settle", goal, steps), run, steps) if self.config.replay_approach else 0
        run(steps - done)

    def _pull_at(self, t: float) -> float:
        """N, the pull motor's control at simulation time ``t`` s (kept as ``self.pull``)."""
        self.pull = min(self.config.max_pull, pull_force(t - self.t0, self.rate, self.amplitude,
                                                         self.frequency, self.phase))
        return self.pull

    def _apply_action(self, a: np.ndarray) -> None:
        self.jaw_goal = self._closure_ctrl(float(a[0]))
        self._run(self.substeps, self.jaw_goal, None)       # None: the episode's pull (compiled schedule)

    def _observe(self) -> np.ndarray:
        pos, fn, ft, rep = self.readings()
        disp = float((pos - self.pos0) @ self.pull_dir)
        return np.array([self.sim.jaw_opening(self.tool_name), *fn, *ft, rep["slipping"], rep["contacts"],
                         self.pull, disp, self.slip_distance], dtype=np.float32)

    def _update(self, a: np.ndarray) -> dict[str, Any]:
        """The slip since the last step, the jaws' total normal force and whether the grasp is lost
        (no contact node, or slip beyond ``max_slip``)."""
        c = self.config
        pos, fn, ft, rep = self.readings()
        self.slip_before = self.slip_distance
        self.slip_distance = self.slip.distance(pos, self.sim.tissue().positions)
        self.normal_total = total = float(np.sum(fn))
        self.peak_force = max(self.peak_force, total)
        self.lost = rep["contacts"] == 0 or self.slip_distance > c.max_slip
        terms: dict[str, Any] = {"pull_force_N": self.pull, "normal_force_N": total,
                                 "least_squeeze_N": least_squeeze(self.pull, self.mu)}
        if self.lost:
            terms["dropped"] = True
        return terms

    def _on_truncate(self):
        ok = self.slip_distance <= self.config.slip_tolerance
        return 0.0, {"success": ok, "is_success": ok}
