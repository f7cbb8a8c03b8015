"""``SurgSim/LayeredPalpation-v0``: find a stiff nodule under the skin of an abdominal wall by pressing.

Tissue: the ``layered`` model (paper 001) of an abdominal wall patch (skin, fat, fascia, muscle,
peritoneum; :mod:`surgsim_envs.geometry.anatomy`), bottom bonded. Each episode hides a stiff
nodule in the fat: the tets within ``nodule_radius`` of a random centre get ``nodule_factor`` x
their Young's modulus, through the tissue contract (``scale_material``), never by model name.

Each step presses a position-controlled 5 mm sphere (:class:`UnilateralProbe`: frictionless,
push-only contact) at a point of the patch to a depth and solves the equilibrium (quasi-static:
one press per step); the force depends on the pose only, not on the presses before.
Action (4,) in [-1, 1]: x, y over the patch, depth over (0, max_depth], commit (> 0 ends the
episode with the guess "the nodule is under this press"). Observation (4,): x (m), y (m),
depth (m), probe force (N). Reward: -press_cost per press; on commit ``1 - distance / size_scale``
(clipped at -1). The episode also ends after ``max_presses``. Forces in newtons.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from surgsim_envs.errors import ConfigError


@dataclass
class LayeredPalpationConfig:
    """size (x, y) m of the wall patch; spacing m of its lattice; max_depth m; nodule radius m and
    Young's modulus factor; press_cost per press; size_scale m of the commit reward; max_presses."""

    size: tuple = (0.08, 0.06)
    spacing: float = 0.005
    max_depth: float = 0.008
    nodule_radius: float = 0.008
    nodule_factor: float = 30.0
    press_cost: float = 0.01
    size_scale: float = 0.03
    max_presses: int = 30
    probe_radius: float = 0.005


_VOLUMES: dict = {}


class LayeredPalpationEnv(gym.Env):
    metadata = {"render_modes": []}

    def __init__(self, config: LayeredPalpationConfig | None = None, render_mode=None):
        from surgsim_envs.contact.unilateral_probe import UnilateralProbe
        from surgsim_envs.geometry.anatomy import abdominal_wall_volume
        from surgsim_envs.tissue import make

        self.config = cfg = config or LayeredPalpationConfig()
        if render_mode is not None:
            raise ConfigError("SurgSim/LayeredPalpation-v0 has no render mode yet; use render_mode=None")
        if not (0 < cfg.max_depth < 0.02 and cfg.max_presses >= 1 and cfg.nodule_factor > 0):
            raise ConfigError(f"LayeredPalpation: bad config {cfg}")
        key = (tuple(cfg.size), cfg.spacing)
        if key not in _VOLUMES:
            _VOLUMES[key] = abdominal_wall_volume(cfg.spacing, size=cfg.size)
        vol = _VOLUMES[key]
        bottom = vol.face_nodes(4)  # no node below: the whole bottom face
        self.tissue = make("layered", vol, fixed=bottom)
        self.tissue.require("quasi_static", task="SurgSim/LayeredPalpation-v0") if hasattr(self.tissue, "require") \
            else None
        self.top = np.flatnonzero(vol.neighbours[:, 5] < 0)
        self.z_top = float(vol.nodes[self.top, 2].max())
        self.probe = UnilateralProbe(self.tissue, self.top, cfg.probe_radius)
        self.centroids = self.tissue.element_centroids()
        fat = vol.layer_names.index("fat")
        self._fat_z = self.centroids[vol.labels == fat, 2]
        self.action_space = gym.spaces.Box(-1.0, 1.0, (4,), np.float32)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (4,), np.float32)
        self.nodule = np.zeros(3)
        self.presses = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        cfg = self.config
        self.probe.move_to((1e3, 1e3, 1e3))
        self.tissue.reset()
        hx, hy = 0.5 * cfg.size[0] - cfg.nodule_radius, 0.5 * cfg.size[1] - cfg.nodule_radius
        z = float(np.clip(np.median(self._fat_z), self._fat_z.min() + cfg.nodule_radius / 2, self._fat_z.max()))
        self.nodule = np.array([self.np_random.uniform(-hx, hx), self.np_random.uniform(-hy, hy), z])
        mask = np.linalg.norm(self.centroids - self.nodule, axis=1) < cfg.nodule_radius
        self.tissue.scale_material("young", 1.0)
        self.tissue.scale_material("young", cfg.nodule_factor, mask=mask)
        self.presses = 0
        return np.zeros(4, dtype=np.float32), {"nodule_tets": int(mask.sum())}

    def step(self, action):
        cfg = self.config
        a = np.clip(np.asarray(action, dtype=np.float64).reshape(4), -1.0, 1.0)
        x, y = a[0] * 0.5 * cfg.size[0], a[1] * 0.5 * cfg.size[1]
        depth = (a[2] + 1.0) / 2.0 * cfg.max_depth
        self.probe.press((x, y, self.z_top + cfg.probe_radius - depth), self.tissue.static_solve)
        force = float(self.probe.force()[2])
        self.presses += 1
        reward = -cfg.press_cost
        dist = float(np.hypot(x - self.nodule[0], y - self.nodule[1]))
        terminated = bool(a[3] > 0.0)
        if terminated:
            reward += max(1.0 - dist / cfg.size_scale, -1.0)
        truncated = self.presses >= cfg.max_presses and not terminated
        obs = np.array([x, y, depth, force], dtype=np.float32)
        return obs, reward, terminated, truncated, {"force_N": force, "distance_m": dist,
                                                    "nodule_centre": self.nodule.copy()}
