"""Common machinery of the SurgSim Gymnasium tasks.

:class:`SurgSimEnv` owns one :class:`~surgsim_envs.scene.Simulation` built once in ``__init__``
and reused by every ``reset`` (only fields, friction and positions are re-randomised), checks
actions (shape, NaN), applies the time limit, renders ("rgb_array" / "human") and fills ``info``
with physical metrics (SI: m, s, N). Subclasses supply a config dataclass and implement
``_build``, ``_randomise``, ``_apply_action`` and ``_observe``, and declare their terms once
(:mod:`surgsim_envs.envs.terms`): ``ACTION`` (the tool the action drives), ``REWARD_TERMS`` and
``TERMINATION_TERMS``. A control step then runs: check the action, ``_apply_action`` (the
physics), ``_update`` (the task's state for the step: samples, grasp, slip; returns info
entries), the termination terms, ``_on_terminate`` if one fires, the reward terms (each value in
``info["reward_terms"]``, summed in declared order), the time limit, ``_observe``.

Configuration: ``gym.make("SurgSim/Palpation-v0", config=PalpationConfig(...))`` or keyword
overrides of config fields (``gym.make(..., control_hz=50)``). ``reset(options=...)`` accepts only
the task's ``OPTIONS`` names (domain randomisation); anything else raises ConfigError by name.

Diverging tissue: by default a :class:`TissueUnstableError` propagates out of ``step`` (as
everywhere in the package). A config with ``on_unstable="terminate"`` (for long RL runs, where one
extreme action must not kill the run) ends the episode instead: ``terminated=True``, reward 0,
``info["unstable"] = True`` and ``info["unstable_reason"]``; the next ``reset`` restores the
simulation.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from surgsim_envs.envs.checks import apply_overrides, check_render_mode
from surgsim_envs.envs.terms.observation import observation_space_of
from surgsim_envs.envs.terms.reward import RewardManager
from surgsim_envs.envs.terms.termination import any_terminated
from surgsim_envs import validate
from surgsim_envs.errors import ConfigError, RenderingUnavailableError, TissueUnstableError


class SurgSimEnv(gym.Env):
    """Base class of the SurgSim tasks (see module docstring).

    config: the task's config dataclass (None = defaults); render_mode: None, "rgb_array" or
    "human"; human_pace: with render_mode="human", steps run at this many times real time, one
    per control period (default 1.0; None runs unpaced, as fast as the physics goes; see
    scene/pacing.py); **overrides: config fields to replace.
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 25}
    #: the task's config dataclass
    config_cls: ClassVar[type]
    #: names accepted in ``reset(options=...)``
    OPTIONS: ClassVar[tuple[str, ...]] = ()
    #: the tool the action drives (an :class:`~surgsim_envs.envs.terms.action.ActionTerm`)
    ACTION: ClassVar[Any] = None
    #: reward terms in summation order (:class:`~surgsim_envs.envs.terms.RewardTerm`)
    REWARD_TERMS: ClassVar[tuple] = ()
    #: termination terms (:class:`~surgsim_envs.envs.terms.TerminationTerm`)
    TERMINATION_TERMS: ClassVar[tuple] = ()

    def __init__(self, config=None, render_mode: str | None = None, *, human_pace: float | None = 1.0, **overrides):
        if config is None:
            config = self.config_cls()
        if not isinstance(config, self.config_cls):
            raise ConfigError(f"config must be a {self.config_cls.__name__}, got {type(config).__name__}")
        self.config = apply_overrides(config, overrides) if overrides else config
        self.config.validate()
        check_render_mode(render_mode, self.metadata["render_modes"])
        self.render_mode = render_mode
        self.metadata = dict(self.metadata, render_fps=int(round(self.config.control_hz)))
        from surgsim_envs.scene.pacing import RealTimePacer, pace_period

        period = pace_period(self.config.control_hz, human_pace)
        #: render_mode="human": holds each step to its control period (None: unpaced)
        self.human_pacer = RealTimePacer(period) if period is not None and render_mode == "human" else None
        self._renderer = None
        self._viewer = None
        self._sims: dict[Any, Any] = {}
        self.sim = None
        self._readings_key = None      # tasks may cache their readings per physics state
        self.rewards = RewardManager(self.REWARD_TERMS, self.config) if self.REWARD_TERMS else None
        self._build()
        self.steps = 0
        self.peak_force = 0.0
        self.episode_return = 0.0

    # -- subclass hooks ---------------------------------------------------------------------
    def _build(self) -> None:
        raise NotImplementedError

    def _randomise(self, options: dict[str, Any]) -> None:
        raise NotImplementedError

    def _apply_action(self, action: np.ndarray) -> None:
        raise NotImplementedError

    def _observe(self) -> np.ndarray:
        raise NotImplementedError

    def _update(self, action: np.ndarray) -> dict[str, Any]:
        """The task's state after the physics of a control step (what its terms read); returns the
        step's info entries."""
        raise NotImplementedError

    def _on_terminate(self) -> dict[str, Any]:
        """A termination term fired: end-of-episode state (read by the reward terms) and info."""
        return {}

    def _evaluate(self, action: np.ndarray) -> tuple[float, bool, dict[str, Any]]:
        """(reward, terminated, info terms) after a control step from the declared terms;
        ``info terms["reward_terms"]`` is {term name: weighted value} summing to the reward."""
        terms = self._update(action)
        terminated = any_terminated(self.TERMINATION_TERMS, self)
        if terminated:
            terms.update(self._on_terminate())
        reward, terms["reward_terms"] = self.rewards.compute(self)
        return reward, terminated, terms

    def _metrics(self) -> dict[str, Any]:
        return {}

    # -- helpers ----------------------------------------------------------------------------
    @property
    def control_dt(self) -> float:
        """Control period (s)."""
        return 1.0 / self.config.control_hz

    @property
    def substeps(self) -> int:
        """Physics steps per control step."""
        return self._step_counts()[0]

    def _step_counts(self) -> tuple[int, int]:
        """(substeps, max_episode_steps), recomputed only when the config's timing fields change."""
        c = self.config
        key = (c.control_hz, c.dt, c.episode_seconds)
        memo = self.__dict__.get("_step_counts_memo")
        if memo is None or memo[0] != key:
            memo = self._step_counts_memo = (key, (max(1, int(round(self.control_dt / c.dt))),
                                                   max(1, int(round(c.episode_seconds * c.control_hz)))))
        return memo[1]

    @property
    def observation_names(self) -> list[str]:
        """Index -> "name [unit]" of every observation entry (from the task's observation terms)."""
        return list(self._obs_names)

    def _set_observation_terms(self, terms) -> None:
        """Build ``observation_space`` (physical bounds) and ``observation_names`` from ObsTerms."""
        self.observation_terms = list(terms)
        self.observation_space, self._obs_names = observation_space_of(self.observation_terms)

    @property
    def max_episode_steps(self) -> int:
        return self._step_counts()[1]

    def check_action(self, action) -> np.ndarray:
        """Action as a float array of the action space's shape, clipped to [-1, 1].

        Raises ConfigError (a ValueError) on a wrong shape or non-finite entries.
        """
        if type(action) is np.ndarray and action.ndim == 1 and action.dtype.char in "fd" \
                and action.shape == self.action_space.shape:
            # fast path of the checks below (same result): the entries as Python floats (exact for
            # float32 / float64), finite if their sum is (a sum that overflows takes the checked
            # path), clipped, into a new float64 array (the caller's array is never modified)
            vals = action.tolist()
            if math.isfinite(sum(vals)):
                return np.array([1.0 if v > 1.0 else (-1.0 if v < -1.0 else v) for v in vals])
        raw = np.asarray(action)
        if raw.dtype.kind not in "iuf":
            raise ConfigError(f"action must be real numbers (float or int) with shape {self.action_space.shape} in "
                              f"[-1, 1], got {action!r} of dtype {raw.dtype} (bool, complex, string and object "
                              "actions are rejected)")
        a = raw.astype(np.float64)
        if a.shape != self.action_space.shape:
            if a.size == int(np.prod(self.action_space.shape)) and a.ndim <= 1:
                a = a.reshape(self.action_space.shape)
            else:
                raise ConfigError(f"action has shape {a.shape}; {type(self).__name__} expects shape "
                                  f"{self.action_space.shape} with entries in [-1, 1]")
        if not np.all(np.isfinite(a)):
            raise ConfigError(f"action contains NaN or inf: {a.tolist()}; give finite numbers in [-1, 1]")
        return np.clip(a, -1.0, 1.0)

    # -- Gymnasium API ----------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=None if seed is None else validate.seed(seed, "reset seed"))
        if options is not None and not isinstance(options, dict):
            raise ConfigError(f"reset options must be a dict of option name -> value or None, got "
                              f"{type(options).__name__} {options!r:.60}; accepted options: {list(self.OPTIONS)}")
        options = dict(options or {})
        unknown = sorted(set(options) - set(self.OPTIONS))
        if unknown:
            raise ConfigError(f"unknown reset option(s) {unknown} for {type(self).__name__}; "
                              f"accepted options: {list(self.OPTIONS)}")
        self.steps = 0
        self.peak_force = 0.0
        self.episode_return = 0.0
        self._readings_key = None          # tasks may cache their readings per physics state
        self._randomise(options)
        obs = self._observe()
        info = self._info({})
        if self.render_mode == "human":
            self.render()
        return obs, info

    def step(self, action):
        if self.sim is None:
            raise ConfigError("call reset() before step()")
        a = self.check_action(action)
        self.steps += 1
        try:
            self._apply_action(a)
        except TissueUnstableError as exc:
            if getattr(self.config, "on_unstable", "raise") != "terminate":
                raise
            return self._unstable_step(exc)
        reward, terminated, terms = self._evaluate(a)
        truncated = (not terminated) and self.steps >= self.max_episode_steps
        if truncated:
            extra_r, extra = self._on_truncate()
            reward += extra_r
            terms.update(extra)
            if "reward_terms" in terms:
                terms["reward_terms"]["final"] = terms["reward_terms"].get("final", 0.0) + float(extra_r)
        self.episode_return += reward
        obs = self._observe()
        info = self._info(terms)
        if self.render_mode == "human":
            self.render()
        return obs, float(reward), bool(terminated), bool(truncated), info

    def _unstable_step(self, exc: TissueUnstableError):
        """End the episode after a tissue divergence (``on_unstable="terminate"``)."""
        self.sim.reset()  # finite state for the last observation; reset() re-randomises as usual
        self._readings_key = None
        obs = self._observe()
        info = self._info({"unstable": True, "unstable_reason": str(exc), "success": False, "is_success": False})
        return obs, 0.0, True, False, info

    def _on_truncate(self) -> tuple[float, dict[str, Any]]:
        return 0.0, {}

    def _info(self, terms: dict[str, Any]) -> dict[str, Any]:
        info = {"time_s": self.sim.time, "steps": self.steps, "peak_force_N": self.peak_force,
                "control_hz": self.config.control_hz, "physics_dt_s": self.sim.dt, "substeps": self.substeps}
        info.update(self._metrics())
        info.update(terms)
        return info

    # -- rendering --------------------------------------------------------------------------
    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without render_mode; pass render_mode='rgb_array' to gym.make")
            return None
        if self.render_mode == "rgb_array":
            return self.render_rgb()
        self._render_human()
        return None

    def render_rgb(self, width: int | None = None, height: int | None = None, camera: str | None = None) -> np.ndarray:
        """(H, W, 3) uint8 frame from ``camera`` (default the config's ``camera``)."""
        from surgsim_envs.scene.render import SceneRenderer

        w = int(width or self.config.render_width)
        h = int(height or self.config.render_height)
        if self._renderer is None or (self._renderer.sim is not self.sim) or \
                (self._renderer.width, self._renderer.height) != (w, h):
            if self._renderer is not None:
                self._renderer.close()
            self._renderer = SceneRenderer(self.sim, w, h)
        return self._renderer.render(camera or self.config.camera)

    def _render_human(self) -> None:
        if self._viewer is None:
            from surgsim_envs.scene.display import require_display

            require_display("render_mode='human'")
            try:
                from surgsim_envs.scene.display import open_viewer

                self._viewer = open_viewer(self.sim.render_model, self.sim.sync_visual(),   # panels hidden
                                           camera=getattr(self.config, "camera", None))
            except Exception as exc:  # no display, or not the main thread on macOS
                raise RenderingUnavailableError(
                    f"render_mode='human' needs a display for mujoco.viewer ({exc}); use render_mode='rgb_array' "
                    "on headless machines") from exc
        self.sim.sync_visual()
        self._viewer.sync()
        if self.human_pacer is not None:
            self.human_pacer.wait()

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self._viewer is not None:
            from surgsim_envs.scene.display import close_viewer

            close_viewer(self._viewer)  # joins the window thread: exiting under it segfaults
            self._viewer = None
