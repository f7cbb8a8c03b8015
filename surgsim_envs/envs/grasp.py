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

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from gymnasium import spaces

from surgsim_envs.envs.base import ObsTerm, check_positive, check_range, check_weights, reward_from_terms, sample
from surgsim_envs.envs.grasp_common import (contact_nodes, contact_reward, excess_force_penalty, is_grasped,
                                            record_progress, slip_fraction)
from surgsim_envs.envs.grasp_scene import GraspSceneConfig, GraspSceneEnv


@dataclass
class GraspConfig(GraspSceneConfig):
    """Grasp-v0 settings (SI units): the shared grasp-scene fields (:class:`GraspSceneConfig`) plus
    the task's target and reward. Ranges are (low, high) sampled uniformly per episode."""

    tissue_subcycles: int | str = "auto"   # 2 tissue + contact steps of dt per MuJoCo step at the defaults
    #                                        (MuJoCo at 0.8 ms; see resolved_subcycles); 1 = one each
    max_step: float = 0.001            # m per control step (5 cm/s at 50 Hz)
    workspace: float = 0.06            # m, wrist target |offset| from home per axis
    target_offset_x: Sequence[float] = (0.012, 0.02)  # m, along the pull direction (out of the organ)
    target_offset_z: Sequence[float] = (0.0, 0.005)   # m, lift
    # reward
    hold_force: float = 0.03           # N, a jaw "holds" above this normal force
    damage_force: float = 1.0          # N per jaw
    force_weight: float = 1.0
    slip_weight: float = 0.1
    progress_weight: float = 5.0
    contact_weight: float = 0.03      # per step, times the fraction of jaws pressing on the tissue
    drop_penalty: float = 0.5
    success_bonus: float = 5.0
    tolerance: float = 0.005           # m

    def validate(self) -> None:
        super().validate()
        for key in ("max_step", "workspace", "hold_force", "damage_force", "tolerance"):
            check_positive(getattr(self, key), f"GraspConfig.{key}")
        check_weights(self, ("force_weight", "slip_weight", "progress_weight", "contact_weight", "drop_penalty",
                             "success_bonus"), "GraspConfig")
        within = f"(within +-workspace={self.workspace:g} m)"
        check_range(self.target_offset_x, f"target_offset_x {within}", -self.workspace, self.workspace)
        check_range(self.target_offset_z, f"target_offset_z {within}", -self.workspace, self.workspace)


class GraspEnv(GraspSceneEnv):
    """Grasp-v0 (see module docstring)."""

    config_cls = GraspConfig
    TASK_ID = "SurgSim/Grasp-v0"
    OPTIONS = ("organ", "mu", "young_scale", "target_offset_x", "target_offset_z")

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

    def _clip_target(self, pos: np.ndarray) -> np.ndarray:
        w = self.config.workspace
        local = (self.frame.T @ (pos - self.home)).tolist()
        local = np.array([w if v > w else (-w if v < -w else v) for v in local])   # = np.clip(local, -w, w)
        return self.home + self.frame @ local

    def _apply_action(self, a: np.ndarray) -> None:
        c, g = self.config, self.gcfg
        self.target = self._clip_target(self.target + a[:3] * c.max_step)
        self.sim.set_tool_target(self.tool_name, self.target)
        radius = g.open_radius - (float(a[3]) + 1.0) / 2.0 * (g.open_radius - g.min_radius)
        self.sim.set_jaw_opening(self.tool_name, min(max(radius, g.min_radius), g.open_radius))
        self.sim.step()

    def _observe(self) -> np.ndarray:
        pos, fn, ft, rep = self._readings()
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
        f0, f1, f2 = fn.tolist()
        total = f0 + f1 + f2                       # = np.sum(fn) (three entries: summed in order)
        if total > self.peak_force:
            self.peak_force = total
        return grasped

    def _evaluate(self, a: np.ndarray):
        c = self.config
        pos, fn, ft, rep = self._readings()
        grasped = self._update_grasp(pos, fn)
        d = self.goal - pos
        dist = math.sqrt(d.dot(d))                 # = np.linalg.norm(d) (its own formula), without the wrapper
        rt = {"excess_force": excess_force_penalty(fn, c.damage_force, c.force_weight),
              "contact": contact_reward(fn, c.hold_force, c.contact_weight), "progress": 0.0, "slip": 0.0,
              "drop": 0.0, "success": 0.0}
        terms: dict[str, Any] = {"grasped": grasped, "distance_to_target_m": dist}
        terminated = False
        if grasped:
            gain, self.best_dist = record_progress(self.best_dist, dist)
            rt["progress"] = c.progress_weight * gain / self.goal_dist0
            rt["slip"] = -c.slip_weight * slip_fraction(rep["slipping"], rep["contacts"])
            self.was_grasped = True
            if dist <= c.tolerance:
                rt["success"] = c.success_bonus
                terminated = True
                terms["success"] = terms["is_success"] = True
        elif self.was_grasped and rep["contacts"] == 0:
            rt["drop"] = -c.drop_penalty
            terminated = True
            terms["dropped"] = True
        self.prev_dist = dist
        reward, terms["reward_terms"] = reward_from_terms(rt)
        return reward, terminated, terms


def grasp_expert(env, close_action: float = 1.0, close_steps: int = 30):
    """Scripted policy: close the jaws, wait, then move straight to the target."""
    state = {"n": 0}

    def policy(obs):
        state["n"] += 1
        if state["n"] <= close_steps:
            return np.array([0, 0, 0, close_action], dtype=np.float32)
        rel = obs[3:6]
        step = env.unwrapped.config.max_step
        return np.array([*np.clip(rel / step * 0.6, -0.6, 0.6), close_action], dtype=np.float32)

    return policy
