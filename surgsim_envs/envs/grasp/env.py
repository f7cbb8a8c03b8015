"""SurgSim/Grasp-v0: close a three-jaw grasper on an organ tip and retract it to a target.

The organ (spleen by default, or a liver lobe; option ``organ``) is held by its ligaments at one
end; the grasper starts open around its other tip (the grasping simulation paper). The agent closes the jaws, then
moves the wrist to a target ``target_offset`` m away (out of and above the organ) without
crushing (jaw normal force above ``damage_force`` N) or losing the grasp.

Action (4,) in [-1, 1]: ``[dx, dy, dz, close]``: wrist target displacement (world frame) of up
to ``max_step`` m per control step, and the jaw opening from fully open (-1) to ``min_radius``
(+1), rate-limited at ``closing_speed`` m/s.

Observation (15,) float32, SI: wrist position (3) m (the grasper only translates: that is its
pose); target minus wrist (3) m; jaw opening (1) m; per-jaw normal force (3) N; per-jaw
tangential force (3) N; slipping contact nodes (1); contact nodes (1).

Reward (shaped so that every stage of the task pays and trying is never worse than doing
nothing): ``contact_weight * (jaws pressing with more than hold_force) / 3`` per step (closing on
the tissue pays at once); ``progress_weight * (d_best - d)+ / initial target distance`` while
grasped, where ``d_best`` is the closest the wrist has come to the target while grasped (a record,
so moving away before grasping or re-grasping cannot farm progress; at most ``progress_weight``
per episode);
``- force_weight * sum(jaw normal - damage_force)+``; ``- slip_weight * slipping fraction``
while grasped; ``- drop_penalty`` on losing a grasp (terminates); ``+ success_bonus`` when the
wrist is within ``tolerance`` m of the target with the organ grasped (terminates, success).

Tissue resolution: ``resolution`` None keeps the task's coarse lattice (spleen 11 mm, liver lobe
15 mm); a number (m) sets the lattice spacing; ``"auto"`` picks the cheapest measured spacing of
the task's model (mass-spring, symplectic) meeting ``error_tolerance`` and ``step_budget_us``
(see :mod:`surgsim_envs.tissue.resolution`).
"""
from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from surgsim_envs.envs.checks import sample
from surgsim_envs.envs.grasp.config import GraspConfig
from surgsim_envs.envs.grasp.scene import GraspSceneEnv
from surgsim_envs.envs.grasp.terms import (GRASP_REWARD_TERMS, GRASP_TERMINATION_TERMS, contact_nodes, is_grasped,
                                          record_progress, total_normal_force)
from surgsim_envs.envs.terms import ObsTerm
from surgsim_envs.envs.terms.action import ActionTerm, jaw_opening, wrist_target
from surgsim_envs.envs.terms.force import vector_norm


class GraspEnv(GraspSceneEnv):
    """Grasp-v0 (see module docstring)."""

    config_cls = GraspConfig
    TASK_ID = "SurgSim/Grasp-v0"
    OPTIONS = ("organ", "mu", "young_scale", "target_offset_x", "target_offset_z")
    ACTION = ActionTerm("grasper", 4, "[dx, dy, dz, close]: wrist target step (world frame), jaw opening")
    REWARD_TERMS = GRASP_REWARD_TERMS
    TERMINATION_TERMS = GRASP_TERMINATION_TERMS

    def _build(self) -> None:
        self.action_space = spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32)
        self._build_scene()
        self._set_observation_terms(self._observation_terms())

    def _observation_terms(self) -> list:
        lo, hi, span = self._reach()
        return [ObsTerm("wrist_position", "m", 3, lo, hi), ObsTerm("target_minus_wrist", "m", 3, -span, span),
                ObsTerm("jaw_opening", "m", 1, 0.0, 2.0 * float(self.gcfg.open_radius)),
                ObsTerm("jaw_normal_force", "N", 3, 0.0), ObsTerm("jaw_tangential_force", "N", 3, 0.0),
                ObsTerm("slipping_contacts", "1", 1, 0.0), ObsTerm("contacts", "1", 1, 0.0)]

    def _randomise(self, options: dict[str, Any]) -> None:
        c, rng = self.config, self.np_random
        self._randomise_common(options)
        ox = sample(rng, options.get("target_offset_x", c.target_offset_x), "target_offset_x", -c.workspace, c.workspace)
        oz = sample(rng, options.get("target_offset_z", c.target_offset_z), "target_offset_z", -c.workspace, c.workspace)
        self.goal = self.home + self.pull_dir * ox + np.array([0.0, 0.0, oz])
        self.target = self.home.copy()
        self.prev_dist = float(np.linalg.norm(self.goal - self.home))
        self.goal_dist0 = max(self.prev_dist, 1e-6)
        self.best_dist = self.goal_dist0

    def _apply_action(self, a: np.ndarray) -> None:
        c, g = self.config, self.gcfg
        self.target = wrist_target(self.target, a[:3], c.max_step, self.home, self.frame, c.workspace)
        self.sim.set_tool_target(self.tool_name, self.target)
        self.sim.set_jaw_opening(self.tool_name, jaw_opening(float(a[3]), g.open_radius, g.min_radius))
        self.sim.step()

    def _observe(self) -> np.ndarray:
        pos, fn, ft, rep = self.readings()
        obs = np.empty(15, dtype=np.float32)
        obs[0:3] = pos
        obs[3:6] = self.goal - pos
        obs[6] = self.tool.jaw_opening(self.sim)
        obs[7:10] = fn
        obs[10:13] = ft
        obs[13] = rep["slipping"]
        obs[14] = rep["contacts"]
        return obs

    def _update_grasp(self, pos, fn) -> bool:
        c = self.config
        grasped = is_grasped(fn, c.hold_force)
        if grasped and not self.slip.active:
            nodes = contact_nodes(self.sim)
            if len(nodes):
                self.slip.start(pos, self.sim.tissue().positions, nodes)
        self.slip_distance = self.slip.distance(pos, self.sim.tissue().positions)
        total = total_normal_force(fn)
        if total > self.peak_force:
            self.peak_force = total
        return grasped

    def _update(self, a: np.ndarray) -> dict[str, Any]:
        """The grasp (and its slip), the distance to the target and its record while grasped, and
        the step's outcome: ``succeeded`` (grasped within tolerance) or ``dropped`` (a grasp lost)."""
        c = self.config
        pos, fn, ft, rep = self.readings()
        self.grasped = grasped = self._update_grasp(pos, fn)
        dist = vector_norm(self.goal - pos)
        terms: dict[str, Any] = {"grasped": grasped, "distance_to_target_m": dist}
        self.progress_gain = 0.0
        self.succeeded = self.dropped = False
        if grasped:
            self.progress_gain, self.best_dist = record_progress(self.best_dist, dist)
            self.was_grasped = True
            if dist <= c.tolerance:
                self.succeeded = True
                terms["success"] = terms["is_success"] = True
        elif self.was_grasped and rep["contacts"] == 0:
            self.dropped = True
            terms["dropped"] = True
        self.prev_dist = dist
        return terms
