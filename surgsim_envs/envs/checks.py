"""Checks shared by the task configs: every one raises ConfigError (a ValueError) naming the field, the
value, its bound and the fix; plus the per-episode sampling of (low, high) ranges."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError


def apply_overrides(config, overrides: dict[str, Any]):
    """Copy of dataclass ``config`` with ``overrides``; ConfigError naming unknown fields."""
    names = {f.name for f in dataclasses.fields(config)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise ConfigError(f"unknown {type(config).__name__} field(s) {unknown}; known fields: {sorted(names)}")
    for key, value in overrides.items():
        validate.config_value(value, f"{type(config).__name__}.{key}")
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


#: m, the smallest tool size, press depth, clearance or tolerance a task takes: the task lattices
#: are millimetres apart, so anything under a tenth of a millimetre resolves nothing (and a probe tip
#: of 1e-300 m overflows the surface sampling it sets)
MIN_TASK_LENGTH = 1e-4
#: m, the largest tool size, press depth, workspace or tolerance a task takes: its scenes are
#: organs and slabs of centimetres (a probe tip of 1e308 m overflows the surface sampling it sets)
MAX_TASK_LENGTH = 1.0


def check_task_length(value, what: str, lo: float = MIN_TASK_LENGTH, hi: float = MAX_TASK_LENGTH) -> float:
    """A length (m) of a task's tool or geometry: finite, in [``lo``, ``hi``] (defaults
    :data:`MIN_TASK_LENGTH`, :data:`MAX_TASK_LENGTH`)."""
    return validate.real(value, what, lo=lo, hi=hi, unit="m",
                         fix=f"give a length in m in [{lo:g}, {hi:g}] (lengths are SI: 5 mm is 0.005)")


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
    if value in integrator_names_of(model_class(config.model)):
        return
    known = sorted({n for m in model_names() for n in integrator_names_of(model_class(m))})
    validate.choice(value, f"{what}.integrator", known, fix=fix)


def integrator_names_of(cls) -> list[str]:
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



def _missing(cls, capabilities) -> list[str]:
    """The capabilities of ``capabilities`` (plus ``implicit_contact`` for a quasi-static model) that
    model class ``cls`` lacks."""
    caps = getattr(cls, "capabilities", ())
    needed = list(capabilities) + (["implicit_contact"] if "quasi_static" in caps else [])
    return [c for c in needed if c not in caps]


def serving_models(capabilities) -> list[str]:
    """Registered tissue models that declare every one of ``capabilities`` (and ``implicit_contact``
    if quasi-static): the models a task with these needs accepts."""
    from surgsim_envs.tissue.registry import get as model_class
    from surgsim_envs.tissue.registry import names

    return [n for n in names() if not _missing(model_class(n), capabilities)]


def require_capabilities(model: str, capabilities, task: str) -> None:
    """Before building: CapabilityError (a ConfigError naming model, capability and task, and the
    registered models that serve the task) unless tissue model ``model`` declares every one of
    ``capabilities`` (tissue contract v2)."""
    from surgsim_envs.tissue.capabilities import CapabilityError
    from surgsim_envs.tissue.registry import get as model_class

    cls = model_class(model)
    try:
        for cap in capabilities:
            cls.require(cap, task=task)
        if "quasi_static" in getattr(cls, "capabilities", ()):
            # a quasi-static model solves an equilibrium every step: the scene's penalty contact (forces
            # that change with the positions) must enter that solve, or the solve chases the contact
            cls.require("implicit_contact", task=f"{task} (a quasi-static model in a contact scene)")
    except CapabilityError as exc:
        raise CapabilityError(f"{exc}; models that serve {task}: {serving_models(capabilities)}") from None


def check_explicit_step(tissue, dt: float, what: str) -> None:
    """After a re-randomised material: ConfigError if the tissue steps explicitly (integrator
    "symplectic") and ``dt`` exceeds its critical step (an implicit or "auto" model is safe)."""
    if getattr(tissue, "integrator", None) != "symplectic":
        return
    crit = tissue.critical_dt()
    if crit < dt:
        raise ConfigError(f"{what} makes the explicit tissue step unstable (critical dt {crit:.2e} s < dt {dt:g} s); "
                          "lower the stiffness ranges or dt, or use integrator 'auto'")


def check_contact_stiffness_per_area(value, what: str) -> None:
    """ConfigError unless ``value`` is None (the scene's stiffness per node), "auto" or a stiffness per
    unit surface area in N/m^3 (:func:`surgsim_envs.scene.contact_options.stiffness_per_area_for`)."""
    if value is None or (isinstance(value, str) and value == "auto"):
        return
    validate.positive(value, what, unit="N/m^3", hi=1e13, fix="'auto', None (200 N/m per node) or e.g. 1e8")


def check_contact_law(value, what: str) -> None:
    """ConfigError unless ``value`` is "linearised", "plane" or "auto"
    (:func:`surgsim_envs.scene.contact_options.contact_law_for`)."""
    if not (isinstance(value, str) and value in ("linearised", "plane", "auto")):
        raise ConfigError(f"{what}={validate.short_repr(value)}; use 'auto' (the plane law where the tissue model "
                          "takes it), 'plane' or 'linearised' (docs/contact.md, \"Friction in a quasi-static step\")")


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



def check_render_mode(render_mode, modes, task: str = "") -> None:
    """Refuse a ``render_mode`` outside ``modes`` (None is always fine), and ``"human"`` without
    a display (raised here; MuJoCo would exit the process later)."""
    if render_mode is not None and render_mode not in modes:
        where = f" by {task}" if task else ""
        raise ConfigError(f"render_mode={render_mode!r} is not supported{where}; use one of {modes} or None")
    if render_mode == "human":
        from surgsim_envs.scene.display import require_display

        require_display("render_mode='human'")

