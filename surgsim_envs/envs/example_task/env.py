"""``SurgSim/ExamplePress-v0``: the worked example of docs/adding_a_task.md.

A probe above a liver slab (the ready-made "palpation" scene, no inclusion) presses straight down;
the agent holds the contact force at ``target_force`` N. Action (1,) in [-1, 1]: the tip depth from
``hover`` m above the rest surface (-1) to ``max_depth`` m below it (+1). Observation (3,) float32:
tip height (m), contact force on the probe along z (N), target force (N). Reward per step:
``- force_weight * |F_z - target_force| / target_force``. The episode ends at the time limit.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from surgsim_envs.envs.base import SurgSimEnv
from surgsim_envs.envs.example_task.config import ExamplePressConfig
from surgsim_envs.envs.example_task.terms import REWARD_TERMS
from surgsim_envs.envs.terms import ObsTerm
from surgsim_envs.envs.terms.action import ActionTerm, probe_target
from surgsim_envs.envs.tissue_setup import tissue_options


class ExamplePressEnv(SurgSimEnv):
    """ExamplePress-v0 (see the module docstring)."""

    config_cls = ExamplePressConfig
    TASK_ID = "SurgSim/ExamplePress-v0"
    ACTION = ActionTerm("probe", 1, "[press]: tip depth from hover (-1) to max_depth (+1)")
    REWARD_TERMS = REWARD_TERMS

    def _build(self) -> None:
        from surgsim_envs.scene import Simulation, palpation_config, palpation_scene

        c = self.config
        cfg = palpation_config(organ="slab", model=c.model)
        t = cfg.tissues[0]
        t.spacing, t.region_materials = c.spacing, None
        t.options = tissue_options(c.model, c.integrator)
        t.volume_options = {"size": tuple(float(s) for s in c.slab_size)}
        t.position = (0.0, 0.0, float(c.slab_size[2]) / 2.0)
        self.surface_z = float(c.slab_size[2])
        probe = cfg.tool("probe")
        probe.tip_radius = c.tip_radius
        probe.position = (0.0, 0.0, self.surface_z + c.tip_radius + c.hover)
        cfg.dt = c.dt
        self.sim = Simulation(palpation_scene(cfg), dt=c.dt, substeps=self.substeps)
        self.home = np.asarray(probe.position, dtype=float)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        top = float(self.home[2])
        self._set_observation_terms([ObsTerm("tip_height", "m", 1, top - float(probe.travel), top + float(probe.travel)),
                                     ObsTerm("contact_force_z", "N", 1),
                                     ObsTerm("target_force", "N", 1, 0.0)])

    def _randomise(self, options: dict[str, Any]) -> None:
        self.sim.reset(seed=int(self.np_random.integers(2**31)))
        self.target = self.home.copy()
        self.sim.set_tool_target("probe", self.target, speed=self.config.probe_speed)

    def _apply_action(self, a: np.ndarray) -> None:
        c = self.config
        self.target = probe_target(self.home.tolist(), [0.0, 0.0, float(a[0])], 0.0, 1.0,
                                   self.surface_z + c.tip_radius, c.hover, c.max_depth)
        self.sim.set_tool_target("probe", self.target, speed=c.probe_speed)
        self.sim.step()

    def readings(self):
        """(probe position (3,) m, force on the probe (3,) N) of the current physics state."""
        return self.sim.tool_position("probe"), self.sim.tool_force("probe")

    def _update(self, a: np.ndarray) -> dict[str, Any]:
        force = self.readings()[1]
        self.peak_force = max(self.peak_force, float(np.linalg.norm(force)))
        return {"force_z_N": float(force[2])}

    def _observe(self) -> np.ndarray:
        pos, force = self.readings()
        return np.array([pos[2], force[2], self.config.target_force], dtype=np.float32)
