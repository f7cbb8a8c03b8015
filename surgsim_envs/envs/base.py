"""Common machinery of the SurgSim Gymnasium tasks.

:class:`SurgSimEnv` owns one :class:`~surgsim_envs.scene.Simulation` built once in ``__init__``
and reused by every ``reset`` (only fields, friction and positions are re-randomised), checks
actions (shape, NaN), applies the time limit, renders ("rgb_array" / "human") and fills ``info``
with physical metrics (SI: m, s, N). Subclasses supply a config dataclass and implement
``_build``, ``_randomise``, ``_apply_action``, ``_observe`` and ``_evaluate`` (reward terms).

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

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError, RenderingUnavailableError, TissueUnstableError


@dataclass(frozen=True)
class ObsTerm:
    """One named observation term: ``size`` entries in ``unit``, physical bounds [low, high]
    (+-inf where none exists, e.g. a contact force)."""

    name: str
    unit: str
    size: int = 1
    low: float = -math.inf
    high: float = math.inf


def observation_space_of(terms) -> tuple[gym.spaces.Box, list[str]]:
    """``(Box, names)`` of a list of :class:`ObsTerm`: float32 bounds per entry and one
    "name [unit]" string per index (``name[i] [unit]`` for multi-entry terms)."""
    lows, highs, names = [], [], []
    for t in terms:
        lows += [t.low] * t.size
        highs += [t.high] * t.size
        names += [f"{t.name} [{t.unit}]"] if t.size == 1 else [f"{t.name}[{i}] [{t.unit}]" for i in range(t.size)]
    box = gym.spaces.Box(np.array(lows, dtype=np.float32), np.array(highs, dtype=np.float32), dtype=np.float32)
    return box, names


def apply_overrides(config, overrides: dict[str, Any]):
    """Copy of dataclass ``config`` with ``overrides``; ConfigError naming unknown fields."""
    names = {f.name for f in dataclasses.fields(config)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise ConfigError(f"unknown {type(config).__name__} field(s) {unknown}; known fields: {sorted(names)}")
    return dataclasses.replace(config, **overrides)


def check_range(value, what: str, lo: float = -math.inf, hi: float = math.inf) -> tuple[float, float]:
    """Validate a (low, high) range of finite numbers inside [lo, hi]; return it as floats."""
    try:
        if isinstance(value, (str, bytes)) or any(not validate.is_real_number(v) for v in value):
            raise TypeError
        a, b = (float(v) for v in value)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(f"{what} must be a (low, high) pair of numbers, got {validate.short_repr(value)}") from None
    if not (math.isfinite(a) and math.isfinite(b) and lo <= a <= b <= hi):
        raise ConfigError(f"{what}={validate.short_repr(value)} must satisfy {lo:g} <= low <= high <= {hi:g}")
    return a, b


def check_positive(value, what: str, hint: str = "") -> float:
    """Validate a positive finite number (:func:`surgsim_envs.validate.positive`)."""
    return validate.positive(value, what, fix=hint or "give a positive finite number")


#: the largest reward weight, bonus or cost a task accepts: a weighted sum of a few hundred terms
#: stays far from float overflow (a weight of 1e308 times a force of 2 N is inf, and inf - inf is NaN)
MAX_REWARD_WEIGHT = 1e6
#: the largest rendered frame side (px): 4096 x 4096 RGB is 50 MB per frame
MAX_RENDER_PX = 4096


def check_weights(config, keys, what: str) -> None:
    """Every field of ``keys`` is a reward weight, bonus or cost: finite, in [0, MAX_REWARD_WEIGHT]
    (the reward formula carries the sign)."""
    for key in keys:
        validate.weight(getattr(config, key), f"{what}.{key}", hi=MAX_REWARD_WEIGHT,
                        fix=f"reward weights are magnitudes in [0, {MAX_REWARD_WEIGHT:g}] (the reward formula "
                            "carries the sign)")


def check_render_size(config, what: str) -> None:
    """``render_width`` / ``render_height``: integers in [1, MAX_RENDER_PX] px; ``camera`` a name."""
    for key in ("render_width", "render_height"):
        validate.integer(getattr(config, key), f"{what}.{key}", lo=1, hi=MAX_RENDER_PX, unit="px",
                         fix=f"frames are at most {MAX_RENDER_PX} px per side")
    validate.text(config.camera, f"{what}.camera", fix="give a camera name of the scene, e.g. 'overview'")


def check_integrator(config, what: str) -> None:
    """``integrator``: a name the task's model has, or one some registered model has (the task then
    takes the model's "auto" or default, as documented), or "auto"; never None, "" or a number."""
    from surgsim_envs.tissue.registry import get as model_class, names as model_names

    value = config.integrator
    fix = "e.g. 'symplectic' (explicit, the default), 'implicit' or 'auto'"
    validate.text(value, f"{what}.integrator", fix=fix)
    if value in _integrator_names(model_class(config.model)):
        return
    known = sorted({n for m in model_names() for n in _integrator_names(model_class(m))})
    validate.choice(value, f"{what}.integrator", known, fix=fix)


def _integrator_names(cls) -> list[str]:
    """The integrator names model class ``cls`` accepts (``integrators`` where it has no
    ``integrator_names``, as :func:`tissue_options` reads them)."""
    return cls.integrator_names() if hasattr(cls, "integrator_names") else list(getattr(cls, "integrators", ()))


def check_episode_seconds(config, what: str) -> float:
    """``episode_seconds`` in (0, validate.MAX_SIM_SECONDS] s."""
    return validate.duration(config.episode_seconds, f"{what}.episode_seconds",
                             fix=f"episodes longer than {validate.MAX_SIM_SECONDS:g} s of simulated time are refused "
                                 "(hours of CPU per episode); e.g. 3.0")


def check_task_resolution(config, what: str) -> None:
    """Validate a task config's ``resolution`` (None, a spacing in m, or "auto"), its
    ``error_tolerance`` (fraction) and ``step_budget_us`` (us per simulated ms): the last two are
    used only by "auto" but checked always (a field that is set is a field that is valid)."""
    from surgsim_envs.tissue.resolution import check_resolution

    check_resolution(config.resolution, f"{what}.resolution")
    check_positive(config.error_tolerance, f"{what}.error_tolerance", "a fraction, e.g. 0.6 for 60 %")
    check_positive(config.step_budget_us, f"{what}.step_budget_us", "us of compute per simulated ms, e.g. 1000")


def check_control_rate(config, what: str) -> None:
    """``control_hz`` must give a control period between one physics step ``dt`` and 1000 physics
    steps (the scene's substep limit), and no longer than the episode: the physical range is
    ``[max(1 / episode_seconds, 1 / (1000 dt)), 1 / dt]`` Hz. ``dt`` and ``episode_seconds`` must be
    valid positive numbers first."""
    from surgsim_envs.scene.config import DT_RANGE, SUBSTEPS_RANGE

    dt = check_positive(config.dt, f"{what}.dt", "the physics step in s, e.g. 4e-4")
    if not DT_RANGE[0] <= dt <= DT_RANGE[1]:
        raise ConfigError(f"{what}.dt={dt!r} s is outside the physics step range [{DT_RANGE[0]:g}, {DT_RANGE[1]:g}] s")
    episode = check_episode_seconds(config, what)
    hz = check_positive(config.control_hz, f"{what}.control_hz", "the control rate in Hz, e.g. 50")
    lo, hi = max(1.0 / episode, 1.0 / (SUBSTEPS_RANGE[1] * dt)), 1.0 / dt
    if not lo * (1 - 1e-9) <= hz <= hi * (1 + 1e-9):
        raise ConfigError(f"{what}.control_hz={hz!r} Hz is outside its physical range [{lo:.4g}, {hi:.4g}] Hz: the "
                          f"control period must be at least one physics step (dt={dt:g} s), at most "
                          f"{SUBSTEPS_RANGE[1]} steps and at most the episode (episode_seconds={episode:g} s); e.g. 50 Hz")


def sphere_mask(centroids: np.ndarray, centre, radius: float) -> np.ndarray:
    """(T,) bool: elements whose rest centroid (``model.element_centroids()``, (T,3) m) lies within
    ``radius`` m of ``centre`` (3,) m; at least the nearest one."""
    d = np.linalg.norm(np.asarray(centroids) - np.asarray(centre, dtype=float)[None], axis=1)
    mask = d < radius
    if not mask.any():
        mask[np.argmin(d)] = True
    return mask


def tissue_options(model: str, integrator: str) -> dict[str, Any]:
    """Constructor options of a task's tissue: ``integrator`` if model ``model`` has it, else its
    "auto" choice (explicit when stable, implicit otherwise), else the model's default."""
    from surgsim_envs.tissue.registry import get as model_class

    names = _integrator_names(model_class(model))
    if integrator in names:
        return {"integrator": integrator}
    return {"integrator": "auto"} if "auto" in names else {}


def explicit_stable_over(tissue, dt: float, max_scale: float) -> bool:
    """True if tissue ``tissue`` (built, unscaled) steps explicitly at ``dt`` s with every element's
    Young's modulus scaled by up to ``max_scale``: ``dt <= stable_dt()`` with the whole tissue at
    ``max_scale`` (a bound for any local scaling up to it: the stiffest node limits the step). The
    material is restored (``scale_material`` is relative to the build) before returning."""
    tissue.scale_material("young", float(max_scale))
    try:
        return float(dt) <= tissue.stable_dt()
    finally:
        tissue.scale_material("young", 1.0)


def integrator_for_range(tissue, dt: float, max_scale: float) -> str | None:
    """The integrator a task must rebuild its tissue with, or None to keep the one built.

    A task asks for "symplectic" by default (the explicit one: fast and, for the mass-spring tasks,
    stable). If the built tissue steps with its explicit integrator (the first of the model's
    ``auto_pair``) but ``dt`` exceeds its :meth:`stable_dt` somewhere in the stiffness
    randomisation (Young's modulus scaled up to ``max_scale``), the task takes the model's "auto"
    instead (explicit while stable at the current state, else implicit). A model without an
    explicit/implicit pair keeps what it has, and the per-episode :func:`check_explicit_step` names
    the problem. Decided from capability (``auto_pair``, ``stable_dt()``), never from a model name."""
    pair = getattr(tissue, "auto_pair", None)
    if pair is None or getattr(tissue, "integrator", None) != pair[0]:
        return None
    return None if explicit_stable_over(tissue, dt, max_scale) else "auto"


def require_capabilities(model: str, capabilities, task: str) -> None:
    """Before building: CapabilityError (a ConfigError naming model, capability and task) unless
    tissue model ``model`` declares every one of ``capabilities`` (tissue contract v2)."""
    from surgsim_envs.tissue.registry import get as model_class

    cls = model_class(model)
    for cap in capabilities:
        cls.require(cap, task=task)
    if "quasi_static" in getattr(cls, "capabilities", ()):
        # a quasi-static model solves an equilibrium every step: the scene's penalty contact (forces
        # that change with the positions) must enter that solve, or the solve chases the contact
        cls.require("implicit_contact", task=f"{task} (a quasi-static model in a contact scene)")


def check_explicit_step(tissue, dt: float, what: str) -> None:
    """After a re-randomised material: ConfigError if the tissue steps explicitly (integrator
    "symplectic") and ``dt`` exceeds its critical step (an implicit or "auto" model is safe)."""
    if getattr(tissue, "integrator", None) != "symplectic":
        return
    crit = tissue.critical_dt()
    if crit < dt:
        raise ConfigError(f"{what} makes the explicit tissue step unstable (critical dt {crit:.2e} s < dt {dt:g} s); "
                          "lower the stiffness ranges or dt, or use integrator 'auto'")


def check_on_unstable(value, what: str) -> None:
    """``on_unstable`` must be "raise" (default) or "terminate" (see the module docstring)."""
    if value not in ("raise", "terminate"):
        raise ConfigError(f"{what}.on_unstable={value!r}; choose 'raise' (default) or 'terminate' (end the "
                          "episode with info['unstable'] instead of raising TissueUnstableError)")


def sample(rng: np.random.Generator, value, what: str, lo: float = -math.inf, hi: float = math.inf) -> float:
    """A number: ``value`` itself if scalar, else uniform in the (low, high) range ``value``."""
    if validate.is_real_number(value):
        return validate.real(value, what, lo=lo, hi=hi, fix=f"give a finite number in [{lo:g}, {hi:g}]")
    a, b = check_range(value, what, lo, hi)
    return float(rng.uniform(a, b)) if b > a else a


def reward_from_terms(terms: dict[str, float]) -> tuple[float, dict[str, float]]:
    """``(sum, terms as floats)`` of weighted reward terms: the reward and ``info["reward_terms"]``."""
    clean = {k: float(v) for k, v in terms.items()}
    return float(sum(clean.values())), clean


def check_render_mode(render_mode, modes, task: str = "") -> None:
    """Refuse a ``render_mode`` outside ``modes`` (None is always fine), and ``"human"`` without
    a display (raised here; MuJoCo would exit the process later)."""
    if render_mode is not None and render_mode not in modes:
        where = f" by {task}" if task else ""
        raise ConfigError(f"render_mode={render_mode!r} is not supported{where}; use one of {modes} or None")
    if render_mode == "human":
        from surgsim_envs.scene.display import require_display

        require_display("render_mode='human'")


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

    def _evaluate(self, action: np.ndarray) -> tuple[float, bool, dict[str, Any]]:
        """(reward, terminated, info terms) after a control step; ``info terms["reward_terms"]`` is
        {term name: weighted value} summing to the reward (:func:`reward_from_terms`)."""
        raise NotImplementedError

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
        super().reset(seed=seed)
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
