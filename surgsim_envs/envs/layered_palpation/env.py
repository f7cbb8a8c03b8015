"""``SurgSim/LayeredPalpation-v0``: find a stiff nodule under the skin of an abdominal wall by pressing.

Tissue: an abdominal wall patch (skin, fat, fascia, muscle, peritoneum;
:mod:`surgsim_envs.geometry.anatomy`), bottom bonded, as a continuum on a layer-conforming lattice
in hexahedra with incompatible modes (``model="fem_hex"``, the default: within the task's force
tolerance at 4 mm) or in tets (``model="fem_static"``), or as the ``layered`` model of Lin et al.
2008 (``model="layered"``, the paper's springs) (:mod:`.wall`). Each episode hides a stiff
nodule in the fat: the points where the elements sample their material (``material_points``: the
centres of tets and springs' tets, the 8 Gauss points of a hexahedron) within ``nodule_radius`` of a
random centre get ``nodule_factor`` x their Young's modulus, through the tissue contract
(``scale_material_at_points``), never by model name. The
reset option ``nodule_position`` (x, y) m places the centre instead (scripted probes and benchmarks
such as ``surgsim bench task-accuracy``); its height is the median height of the fat's tets either way.

Each step presses a position-controlled sphere (frictionless, push-only contact: :mod:`.wall` names
the probe of each model) at a point of the patch to a depth and solves the equilibrium (quasi-static:
one press per step); the force depends on the pose only, not on the presses before.
Action (4,) in [-1, 1]: x, y over the patch, depth over [0, max_depth], commit (> 0 ends the
episode with the guess "the nodule is under this press"). Observation (4,): x (m), y (m),
depth (m), probe force (N, >= 0). Reward: -press_cost per press; on commit
``1 - distance / size_scale`` (clipped at -1). The episode also ends after ``max_presses``.
``info["success"]``: committed within ``nodule_radius`` of the nodule's centre (in x, y).

Checks as the other tasks (:mod:`surgsim_envs.envs.checks`): config fields by name, bound and fix
(ConfigError), keyword overrides in ``gym.make``, actions by ``SurgSimEnv.check_action`` (shape,
dtype, NaN), reset options. Rendering (``render_mode="rgb_array"``) and the dm_control loader
(and ``"human"``, a MuJoCo viewer where a display exists) use a MuJoCo scene of the same wall (:mod:`surgsim_envs.envs.layered_palpation.scene`), built on first use;
its clock runs ``1 / control_hz`` s per press (a nominal press rate: the physics is quasi-static).
Forces in newtons, lengths in metres. The reward terms are declared in :mod:`.terms`.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any

import gymnasium as gym
import numpy as np

from surgsim_envs.envs.base import SurgSimEnv
from surgsim_envs.envs.checks import apply_overrides, check_render_mode
from surgsim_envs.envs.layered_palpation.config import LayeredPalpationConfig
from surgsim_envs.envs.layered_palpation.terms import REWARD_TERMS
from surgsim_envs.envs.terms import ObsTerm, RewardManager, observation_space_of
from surgsim_envs.envs.terms.action import ActionTerm
from surgsim_envs import validate
from surgsim_envs.errors import ConfigError, TissueUnstableError



class LayeredPalpationEnv(gym.Env):
    """See the module docstring. config: a :class:`LayeredPalpationConfig` (None = defaults);
    render_mode: None, "rgb_array" or "human"; **overrides: config fields to replace."""

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 1}
    config_cls = LayeredPalpationConfig
    #: reset options: ``nodule_position`` (x, y) m places the nodule's centre (scripted probes, benchmarks);
    #: without it the nodule is drawn from the seed
    OPTIONS: tuple = ("nodule_position",)
    ACTION = ActionTerm("probe", 4, "[x, y, depth, commit]: press site over the patch, depth, commit")
    REWARD_TERMS = REWARD_TERMS
    #: the shape/dtype/NaN checks of every other task
    check_action = SurgSimEnv.check_action

    def __init__(self, config: LayeredPalpationConfig | None = None, render_mode: str | None = None, **overrides):
        from surgsim_envs.envs.layered_palpation.wall import BUILDERS

        if config is None:
            config = LayeredPalpationConfig()
        if not isinstance(config, LayeredPalpationConfig):
            raise ConfigError(f"config must be a LayeredPalpationConfig, got {type(config).__name__}")
        self.config = cfg = apply_overrides(config, overrides) if overrides else dataclasses.replace(config)
        cfg.validate()
        check_render_mode(render_mode, self.metadata["render_modes"], "SurgSim/LayeredPalpation-v0")
        self.render_mode = render_mode
        self.metadata = dict(self.metadata, render_fps=max(1, int(round(cfg.control_hz))))
        self.wall = wall = BUILDERS[cfg.model](cfg)
        self.tissue, self.top, self.z_top, self.probe = wall.tissue, wall.top, wall.z_top, wall.probe
        self.material_points = wall.tissue.material_points()   # (T, Q, 3) m
        self._fat_z = wall.fat_z
        self._inside = None
        hx, hy = 0.5 * float(cfg.size[0]), 0.5 * float(cfg.size[1])
        self.action_space = gym.spaces.Box(-1.0, 1.0, (4,), np.float32)
        self.observation_terms = [ObsTerm("press_x", "m", 1, -hx, hx), ObsTerm("press_y", "m", 1, -hy, hy),
                                  ObsTerm("press_depth", "m", 1, 0.0, float(cfg.max_depth)),
                                  ObsTerm("probe_force", "N", 1, 0.0, math.inf)]
        self.observation_space, self._obs_names = observation_space_of(self.observation_terms)
        self.rewards = RewardManager(REWARD_TERMS, cfg)
        self.nodule = np.zeros(3)
        self.presses = 0
        self.steps = 0
        self._centre = np.array([0.0, 0.0, self.z_top + 0.03])
        self._scene = None
        self._renderer = None
        self._viewer = None
        self._reset_done = False

    # -- properties the other tasks have --------------------------------------------------------
    @property
    def observation_names(self) -> list[str]:
        """Index -> "name [unit]" of every observation entry."""
        return list(self._obs_names)

    @property
    def control_dt(self) -> float:
        """s per press on the nominal clock."""
        return 1.0 / self.config.control_hz

    @property
    def max_episode_steps(self) -> int:
        return int(self.config.max_presses)

    @property
    def sim(self):
        """The MuJoCo scene mirroring the wall and the probe (built on first use; see module docstring)."""
        if self._scene is None:
            from surgsim_envs.envs.layered_palpation.scene import PressScene

            cfg = self.config
            self._scene = PressScene(self.tissue, cfg.spacing, cfg.size, cfg.probe_radius, cfg.render_width,
                                     cfg.render_height, model=cfg.model, organ=self.wall.organ)
            self._show()
        return self._scene.sim

    def _show(self) -> None:
        if self._scene is not None:
            self._scene.show(self.tissue, self._centre, self.presses * self.control_dt)

    # -- Gymnasium API ------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        if options is not None and not isinstance(options, dict):
            raise ConfigError(f"reset options must be a dict or None, got {type(options).__name__}")
        unknown = sorted(set(options or {}) - set(self.OPTIONS))
        if unknown:
            raise ConfigError(f"unknown reset option(s) {unknown} for LayeredPalpationEnv; it accepts "
                              f"{list(self.OPTIONS)} (without them the nodule is placed from the seed)")
        super().reset(seed=None if seed is None else validate.seed(seed, "reset seed"))
        cfg = self.config
        self.wall.lift()    # every node free
        self.tissue.reset()
        hx, hy = 0.5 * cfg.size[0] - cfg.nodule_radius, 0.5 * cfg.size[1] - cfg.nodule_radius
        z = float(np.clip(np.median(self._fat_z), self._fat_z.min() + cfg.nodule_radius / 2, self._fat_z.max()))
        placed = (options or {}).get("nodule_position")
        if placed is None:
            self.nodule = np.array([self.np_random.uniform(-hx, hx), self.np_random.uniform(-hy, hy), z])
        else:
            self.nodule = np.array([*self._nodule_xy(placed, hx, hy), z])
        inside = np.linalg.norm(self.material_points - self.nodule, axis=2) < cfg.nodule_radius
        if self._inside is None or not np.array_equal(inside, self._inside):   # unchanged: keep a factorised stiffness
            self.tissue.scale_material_at_points("young", np.where(inside, float(cfg.nodule_factor), 1.0))
            self._inside = inside
        self.wall.ready()
        self.presses = self.steps = 0
        self._centre = np.array([0.0, 0.0, self.z_top + 0.03])
        self._reset_done = True
        self._show()
        if self.render_mode == "human":
            self.render()
        return np.zeros(4, dtype=np.float32), {"nodule_tets": int(inside.any(axis=1).sum()), "nodule_centre": self.nodule.copy()}

    @staticmethod
    def _nodule_xy(value, hx: float, hy: float) -> tuple[float, float]:
        """The ``nodule_position`` reset option as (x, y) m, inside the patch by the nodule's radius."""
        if not validate.has_length(value, 2):
            raise ConfigError(f"reset option nodule_position={validate.short_repr(value)} must be a pair (x, y) "
                              "in m, e.g. (0.02, 0.01)")
        out = []
        for k, (v, h) in enumerate(zip(value, (hx, hy))):
            out.append(validate.real(v, f"reset option nodule_position[{k}]", lo=-h, hi=h, unit="m",
                                     fix="a centre at least nodule_radius inside the patch edge"))
        return out[0], out[1]

    def step(self, action):
        if not self._reset_done:
            raise ConfigError("call reset() before step()")
        a = self.check_action(action)
        cfg = self.config
        x, y = a[0] * 0.5 * cfg.size[0], a[1] * 0.5 * cfg.size[1]
        depth = (a[2] + 1.0) / 2.0 * cfg.max_depth
        self._centre = np.array([x, y, self.z_top + cfg.probe_radius - depth])
        self.wall.press(self._centre)
        force = float(self.probe.force()[2])
        if not math.isfinite(force):
            raise TissueUnstableError(cfg.model, 0.0, math.inf, f"the static solve gave a non-finite probe force "
                                      f"{force!r} at press ({x:.4g}, {y:.4g}) m, depth {depth:.4g} m")
        force = max(force, 0.0)   # reactions are compressive; a round-off below 0 reads 0
        self.presses += 1
        self.steps += 1
        dist = self.distance = float(np.hypot(x - self.nodule[0], y - self.nodule[1]))
        terminated = self.committed = bool(a[3] > 0.0)
        reward, terms = self.rewards.compute(self)
        truncated = self.presses >= cfg.max_presses and not terminated
        self._show()
        if self.render_mode == "human":
            self.render()
        obs = np.array([x, y, depth, force], dtype=np.float32)
        success = bool(terminated and dist <= cfg.nodule_radius)
        return obs, reward, terminated, truncated, {
            "force_N": force, "distance_m": dist, "nodule_centre": self.nodule.copy(), "presses": self.presses,
            "contact_nodes": int(len(self.probe.nodes)), "active_set_iterations": int(self.probe.last_iterations),
            "reward_terms": terms, "success": success, "is_success": success}

    # -- rendering ----------------------------------------------------------------------------
    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without render_mode; pass render_mode='rgb_array' to gym.make")
            return None
        if self.render_mode == "rgb_array":
            return self.render_rgb()
        self._render_human()
        return None

    def _render_human(self) -> None:
        sim = self.sim
        if self._viewer is None:
            from surgsim_envs.errors import RenderingUnavailableError

            try:
                from surgsim_envs.scene.display import open_viewer

                self._viewer = open_viewer(sim.render_model, sim.sync_visual(),   # panels hidden
                                           camera=getattr(self.config, "camera", None))
            except Exception as exc:  # no display, or not the main thread on macOS
                raise RenderingUnavailableError(
                    f"render_mode='human' needs a display for mujoco.viewer ({exc}); use render_mode='rgb_array' "
                    "on headless machines") from exc
        sim.sync_visual()
        self._viewer.sync()

    def render_rgb(self, width: int | None = None, height: int | None = None, camera: str | None = None) -> np.ndarray:
        """(H, W, 3) uint8 frame of the wall and the probe at the last press."""
        from surgsim_envs.scene.render import SceneRenderer

        sim = self.sim
        w, h = int(width or self.config.render_width), int(height or self.config.render_height)
        if self._renderer is None or (self._renderer.width, self._renderer.height) != (w, h):
            if self._renderer is not None:
                self._renderer.close()
            self._renderer = SceneRenderer(sim, w, h)
        return self._renderer.render(camera or self.config.camera)

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self._viewer is not None:
            from surgsim_envs.scene.display import close_viewer

            close_viewer(self._viewer)
            self._viewer = None
