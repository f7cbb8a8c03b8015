"""The scenario file schema (TOML), as dataclasses, with loading and validation.

A scenario file has these tables (every key is optional unless marked *required*; SI units)::

    [scenario]                 # what is run
    name = "spleen_grasp"      # *required*, used for the output folder and the report
    description = "..."
    scene = "grasp"            # ready-made scene: "palpation" (probe, slab with inclusion) or "grasp"
                               # (three-jaw grasper around the spleen tip). Omit when `task` is given.
    task = ""                  # a registered Gymnasium task id ("SurgSim/Palpation-v0"): a policy rollout
    seed = 0
    sample_period = 0.01       # s between recorded samples
    duration_scale = 1.0       # multiplies every phase duration (the CLI's --duration-scale multiplies again)

    [scene]                    # overrides of the ready-made scene (all optional)
    organ = "spleen"           # geometry volume name (make_volume)
    model = "mass_spring"      # tissue model registry name
    material = "spleen"        # material preset name
    spacing = 0.006            # m, node spacing
    mu = 0.6                   # tool-tissue Coulomb friction coefficient
    dt = 0.001                 # s, physics step
    inclusion_xy = [0.01, 0.0] # m, where the hidden inclusion sits (palpation)

    [trainee]                  # who drives the phases by default
    driver = "script"          # "script" | "device" | "policy"
    device = "scripted"        # device spec for driver = "device": scripted | replay:FILE | keyboard | udp:PORT
    script = ""                # scripted device: path to a JSON/TOML trajectory (default: the phase motion)
    policy = ""                # driver = "policy": "module:function" or an SB3 .zip file
    tremor = 0.0               # m, tremor amplitude of the default simulated hand (device "scripted")

    [[phases]]                 # in order; see surgsim_envs.scenarios.phases for every type and key
    type = "close_jaws"        # approach | close_jaws | hold | pull | press | palpate | release
    duration = 4.0             # s
    ...                        # type-specific keys (opening, distance, force, depth, at, ...)
    driver = "script"          # optional per-phase override of [trainee]

    [scoring]
    safety_limit = 3.0         # N, normal force above which time counts as a safety violation
    [scoring.criteria.peak_force]   # one table per criterion (see scoring.CRITERIA)
    target = 2.0               # full marks at or below this value
    limit = 4.0                # zero marks at or above (the criterion fails)
    weight = 1.0

    [sweep]                    # optional: one run per value; keys are [scene] keys
    mu = [0.6, 0.8, 1.0]

    [policy]                   # only with scenario.task (Gymnasium rollout)
    file = "surgsim_envs.scenarios.policies:palpation_scan"
    episodes = 1
    max_steps = 200
    env_kwargs = {}

Unknown keys, wrong types, bad values and impossible phase orders raise
:class:`~surgsim_envs.errors.ConfigError` naming the key, its value and (for files) the line,
before any simulation is built (so ``surgsim run --check`` catches them). Beyond types, values are
checked against :data:`LIMITS` (e.g. ``scene.dt`` in (0, 5 ms], ``scene.spacing`` >= 2 mm, phase
durations <= 600 s, a whole run <= 3,600 s of simulated time); names against their registries
(organ, tissue model, material preset, Gymnasium task id, built-in policy); files named by
``replay:FILE``, ``trainee.script`` and policies must exist (relative paths are taken relative to
the scenario's folder, then the working directory). Policies follow the trust model of
:mod:`surgsim_envs.scenarios.policies`: code-loading ones need ``allow_code`` (``--allow-code``).
The scenario ``name`` becomes a folder name: letters, digits, ``_``, ``-``, ``.``, not starting
with ``.`` (so ``".."`` cannot escape the output folder), at most 100 characters. Files larger than
1 MB and nesting deeper than the TOML parser can follow are refused with a ConfigError.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import re
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from surgsim_envs.errors import ConfigError


SCENES = ("palpation", "grasp")
DRIVERS = ("script", "device", "policy")
MAX_FILE_BYTES = 1_000_000
NAME_PATTERN = r"[A-Za-z0-9_][A-Za-z0-9_.\-]{0,99}"
#: rule -> (low, high, low inclusive, unit): limits of numeric values (high always inclusive),
#: checked at load time; a phase field ``f`` uses rule ``phase.f`` (arrays: every element)
LIMITS: dict[str, tuple[float, float, bool, str]] = {
    "scenario.sample_period": (1e-4, 10.0, True, "s"),
    "scenario.duration_scale": (0.0, 100.0, False, ""),
    "scenario.seed": (0, 2**32 - 1, True, ""),
    "scene.spacing": (2e-3, 0.05, True, "m"),
    "scene.dt": (0.0, 5e-3, False, "s"),
    "scene.mu": (0.0, 10.0, True, ""),
    "scene.inclusion_xy": (-0.1, 0.1, True, "m"),
    "trainee.tremor": (0.0, 0.01, True, "m"),
    "phase.duration": (0.0, 600.0, False, "s"),
    "phase.depth": (0.0, 0.05, False, "m"),
    "phase.clearance": (0.0, 0.1, True, "m"),
    "phase.distance": (0.0, 0.2, False, "m"),
    "phase.force": (0.0, 100.0, False, "N"),
    "phase.gain": (0.0, 100.0, False, ""),
    "phase.max_speed": (0.0, 1.0, False, "m/s"),
    "phase.opening": (0.0, 0.1, False, "m"),
    "phase.at": (-0.2, 0.2, True, "m"),
    "phase.region": (-0.2, 0.2, True, "m"),
    "phase.offset": (-0.2, 0.2, True, "m"),
    "phase.above": (-0.2, 0.2, True, "m"),
    "phase.direction": (-1e3, 1e3, True, ""),
    "phase.grid": (1, 400, True, "presses per axis"),
    "policy.episodes": (1, 1000, True, ""),
    "policy.max_steps": (1, 1_000_000, True, "steps"),
    "scoring.safety_limit": (0.0, 1e3, False, "N"),
    # the score is a weighted mean: weights up to 1e6 keep the sums of a few criteria far from overflow
    "criterion.weight": (0.0, 1e6, True, ""),
    "criterion.target": (-1e12, 1e12, True, ""),
    "criterion.limit": (-1e12, 1e12, True, ""),
}
MAX_RUN_DURATION = 3600.0  # s of simulated time per run (phases x duration scale)
MAX_GRID_PRESSES = 400


@dataclass
class ScenarioMeta:
    """The ``[scenario]`` table. ``sample_period`` s; ``duration_scale`` multiplies phase durations."""

    name: str = ""
    description: str = ""
    scene: str = ""
    task: str = ""
    seed: int = 0
    sample_period: float = 0.01
    duration_scale: float = 1.0


@dataclass
class SceneOverrides:
    """The ``[scene]`` table: changes to the ready-made scene. ``None`` keeps the scene's value.

    organ: volume name; model: tissue model; material: preset name; spacing: m;
    mu: tool-tissue friction coefficient; dt: s physics step; inclusion_xy: (2,) m x, y of the
    stiff inclusion's centre (organ "slab_inclusion" only).
    """

    organ: str | None = None
    model: str | None = None
    material: str | None = None
    spacing: float | None = None
    mu: float | None = None
    dt: float | None = None
    inclusion_xy: tuple[float, float] | None = None


@dataclass
class TraineeSpec:
    """The ``[trainee]`` table: default driver of every phase (see module docstring)."""

    driver: str = "script"
    device: str = "scripted"
    script: str = ""
    policy: str = ""
    tremor: float = 0.0


@dataclass
class CriterionSpec:
    """One scoring criterion: full marks at or below ``target``, zero at or above ``limit``
    (linear in between; the criterion fails at or above ``limit``), weighted by ``weight``.
    For ``completion`` target/limit are ignored."""

    target: float = 0.0
    limit: float = 1.0
    weight: float = 1.0


@dataclass
class ScoringSpec:
    """The ``[scoring]`` table: ``safety_limit`` N and the criteria by name."""

    safety_limit: float = 3.0
    criteria: dict[str, CriterionSpec] = field(default_factory=dict)


@dataclass
class PolicySpec:
    """The ``[policy]`` table of a Gymnasium rollout scenario (``scenario.task``)."""

    file: str = ""
    episodes: int = 1
    max_steps: int = 200
    env_kwargs: dict = field(default_factory=dict)


@dataclass
class Scenario:
    """A validated scenario. ``phases`` are :class:`~surgsim_envs.scenarios.phases.Phase` objects;
    ``sweep`` maps a [scene] key to its values; ``source`` is the file it came from (or None)."""

    meta: ScenarioMeta
    scene: SceneOverrides = field(default_factory=SceneOverrides)
    trainee: TraineeSpec = field(default_factory=TraineeSpec)
    phases: list = field(default_factory=list)
    scoring: ScoringSpec = field(default_factory=ScoringSpec)
    sweep: dict[str, list] = field(default_factory=dict)
    policy: PolicySpec | None = None
    source: Path | None = None
    #: folder that relative file names are resolved against (the scenario file's folder)
    folder: Path | None = None
    #: code-loading policies allowed (``--allow-code``); see scenarios.policies
    allow_code: bool = False
    #: a policy reference given on the command line (trusted: may name any module or file)
    trusted_policy: str = ""

    @property
    def name(self) -> str:
        return self.meta.name

    def runs(self) -> list[tuple[dict, "Scenario"]]:
        """One (sweep values, scenario with those [scene] values) per run; one run without a sweep."""
        if not self.sweep:
            return [({}, self)]
        keys = list(self.sweep)
        n = len(self.sweep[keys[0]])
        out = []
        for i in range(n):
            values = {k: self.sweep[k][i] for k in keys}
            sc = copy.deepcopy(self)
            sc.sweep = {}
            for k, v in values.items():
                setattr(sc.scene, k, v)
            out.append((values, sc))
        return out

    def scaled(self, factor: float) -> "Scenario":
        """A copy with every phase duration multiplied by ``factor`` (> 0)."""
        if isinstance(factor, bool) or not isinstance(factor, (int, float)) or not (0 < factor <= 100):
            raise ConfigError(f"duration scale must be a number in (0, 100], got {factor!r}")
        sc = copy.deepcopy(self)
        sc.meta.duration_scale = self.meta.duration_scale * float(factor)
        total = sc.run_duration()
        if total > MAX_RUN_DURATION:
            raise ConfigError(f"with duration scale {factor!r} one run lasts {total:g} s of simulated time, more than "
                              f"the {MAX_RUN_DURATION:g} s limit; use a smaller scale")
        return sc

    def run_duration(self) -> float:
        """Simulated seconds of one run (phase durations times the duration scale)."""
        return sum(p.duration for p in self.phases) * self.meta.duration_scale


# ----------------------------------------------------------------------------------------------
# Locating keys in the TOML text (tomllib reports no positions for valid files)
class KeyLocator:
    """Maps a key path such as ``("phases", 2, "duration")`` to its 1-based line in the TOML text."""

    _HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
    _KEY = re.compile(r"^\s*(\"[^\"]+\"|'[^']+'|[A-Za-z0-9_.\-]+)\s*=")

    def __init__(self, text: str | None):
        self.lines: dict[tuple, int] = {}
        if not text:
            return
        table: tuple = ()
        counts: dict[tuple, int] = {}
        for no, line in enumerate(text.splitlines(), start=1):
            m = self._HEADER.match(line)
            if m and not self._KEY.match(line):
                parts = tuple(p.strip().strip("\"'") for p in m.group(2).split("."))
                if m.group(1) == "[[":
                    i = counts.get(parts, 0)
                    counts[parts] = i + 1
                    table = parts + (i,)
                else:
                    table = parts
                self.lines.setdefault(table, no)
                continue
            k = self._KEY.match(line)
            if k:
                key = tuple(p.strip().strip("\"'") for p in k.group(1).split("."))
                self.lines.setdefault(table + key, no)

    def line(self, path: tuple) -> int | None:
        """Line of ``path`` or of its nearest enclosing table; None when unknown."""
        p = tuple(path)
        while p:
            if p in self.lines:
                return self.lines[p]
            p = p[:-1]
        return None


class ValidationContext:
    """Where a value being validated came from (file or command line, its line numbers, its
    folder), so that an error names the key and the line."""

    def __init__(self, source: str, locator: KeyLocator, folder: Path | None = None):
        self.source, self.locator, self.folder = source, locator, folder

    def error(self, path: tuple, message: str) -> ConfigError:
        key = _dotted(path)
        line = self.locator.line(path)
        where = f"{self.source}" + (f", line {line}" if line else "")
        return ConfigError(f"{where}: {key}: {message}")


def _dotted(path: tuple) -> str:
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out or "<top level>"


# ----------------------------------------------------------------------------------------------
# Generic typed construction of dataclasses from TOML tables
def _check_type(value: Any, hint: Any, path: tuple, ctx: ValidationContext) -> Any:
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if hint is Any:
        return value
    if origin in (typing.Union, getattr(__import__("types"), "UnionType", None)):
        if value is None and type(None) in args:
            return None
        errors = []
        for a in args:
            if a is type(None):
                continue
            try:
                return _check_type(value, a, path, ctx)
            except ConfigError as exc:
                errors.append(exc)
        raise errors[0]
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ctx.error(path, f"expected a number, got {value!r} ({type(value).__name__})")
        try:
            number = float(value)
        except OverflowError:           # an integer too large for a float
            number = math.inf
        if not math.isfinite(number):
            raise ctx.error(path, f"expected a finite number, got {_short(value)}")
        return number
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ctx.error(path, f"expected an integer, got {value!r} ({type(value).__name__})")
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise ctx.error(path, f"expected true or false, got {value!r} ({type(value).__name__})")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise ctx.error(path, f"expected a string, got {_short(value)} ({type(value).__name__})")
        return value
    if origin in (list, tuple):
        if not isinstance(value, list):
            raise ctx.error(path, f"expected an array, got {value!r} ({type(value).__name__})")
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise ctx.error(path, f"expected an array of {len(args)} values, got {len(value)}: {value!r}")
            return tuple(_check_type(v, a, path + (i,), ctx) for i, (v, a) in enumerate(zip(value, args)))
        inner = args[0] if args else Any
        out = [_check_type(v, inner, path + (i,), ctx) for i, v in enumerate(value)]
        return tuple(out) if origin is tuple else out
    if origin is dict or hint is dict:
        if not isinstance(value, dict):
            raise ctx.error(path, f"expected a table, got {value!r} ({type(value).__name__})")
        if args and dataclasses.is_dataclass(args[1]):
            return {k: build_dataclass(args[1], v, path + (k,), ctx) for k, v in value.items()}
        return dict(value)
    if dataclasses.is_dataclass(hint):
        return build_dataclass(hint, value, path, ctx)
    return value  # pragma: no cover - unsupported annotation: accept as is


def build_dataclass(cls, table: Any, path: tuple, ctx: ValidationContext, skip: tuple = ()):
    """Instance of dataclass ``cls`` from the TOML ``table``; ConfigError names unknown keys and bad types."""
    if not isinstance(table, dict):
        raise ctx.error(path, f"expected a table, got {table!r} ({type(table).__name__})")
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls) if f.init]
    kwargs = {}
    for key, value in table.items():
        if key in skip:
            continue
        if key not in names:
            close = [n for n in names if n.startswith(key[:3])] or names
            raise ctx.error(path + (key,), f"unknown key {key!r} (value {value!r}); allowed keys here: "
                                           f"{', '.join(sorted(close if len(close) < len(names) else names))}")
        kwargs[key] = _check_type(value, hints[key], path + (key,), ctx)
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        raise ctx.error(path, str(exc)) from None


# ----------------------------------------------------------------------------------------------
_TOP = ("scenario", "scene", "trainee", "phases", "scoring", "sweep", "policy")


def _limit(ctx: ValidationContext, path: tuple, rule: str, value) -> None:
    """Check ``value`` (a number or nested arrays of numbers) against ``LIMITS[rule]``."""
    if value is None:
        return
    if isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            _limit(ctx, path + (i,), rule, v)
        return
    lo, hi, lo_inclusive, unit = LIMITS[rule]
    ok = (value >= lo if lo_inclusive else value > lo) and value <= hi
    if not ok:
        u = f" {unit}" if unit else ""
        raise ctx.error(path, f"{value!r} is out of range: must be {'>=' if lo_inclusive else '>'} {lo:g}{u} and "
                              f"<= {hi:g}{u}")


def resolve_data_file(name: str, folder: Path | None) -> Path:
    """A file named in a scenario: absolute as given; relative to the scenario's ``folder`` when
    it exists there, else relative to the working directory."""
    p = Path(name)
    if not p.is_absolute() and folder is not None and (folder / p).is_file():
        return folder / p
    return p


def _check_file(ctx: ValidationContext, path: tuple, name: str, folder: Path | None, what: str) -> None:
    if not resolve_data_file(name, folder).is_file():
        where = f"{folder} or the working directory" if folder is not None else "the working directory"
        raise ctx.error(path, f"{what} file {name!r} not found (looked in {where})")


def validate_driver(ctx: ValidationContext, path: tuple, driver: str, device: str, policy: str, folder: Path | None = None,
                    allow_code: bool = True, trusted: bool = True, check_files: bool = False) -> None:
    """Check a driver name, the device spec (files exist when ``check_files``) and the policy
    reference under the trust model (see :func:`surgsim_envs.scenarios.policies.check_policy_reference`)."""
    if driver not in DRIVERS:
        raise ctx.error(path + ("driver",), f"unknown driver {driver!r}; choose one of {', '.join(DRIVERS)}")
    if driver == "device":
        from surgsim_envs.haptics.device_kinds import device_kind

        try:
            kind, arg = device_kind(device)
        except ConfigError as exc:
            raise ctx.error(path + ("device",), str(exc)) from None
        if kind.remote and not trusted:
            raise ctx.error(path + ("device",), f"device {device!r} opens a network port, which a scenario file may "
                                                "not do (sharing a scenario must not open a port); pass --device "
                                                f"{device} on the command line instead")
        if kind.file_arg and check_files:
            _check_file(ctx, path + ("device",), arg, folder, kind.name)
    if driver == "policy":
        if not policy:
            raise ctx.error(path + ("policy",), "driver 'policy' needs a policy: a .npz data policy, 'builtin:NAME' "
                                                "or (with --allow-code) 'file.py:function'")
        check_policy(ctx, path + ("policy",), policy, folder, allow_code, trusted)


def check_policy(ctx: ValidationContext, path: tuple, ref: str, folder: Path | None, allow_code: bool, trusted: bool) -> None:
    """:func:`~surgsim_envs.scenarios.policies.check_policy_reference` with the key's line."""
    from surgsim_envs.scenarios.policies import check_policy_reference

    try:
        check_policy_reference(ref, folder, allow_code=allow_code, trusted=trusted)
    except ConfigError as exc:
        raise ctx.error(path, str(exc)) from None


def _check_registered(ctx: ValidationContext, path: tuple, value: str | None, known: list, what: str) -> None:
    if value is not None and value not in known:
        raise ctx.error(path, f"unknown {what} {value!r}; choose one of {', '.join(map(str, known))}")


def _check_scene_value(ctx: ValidationContext, path: tuple, key: str, value) -> None:
    """Range and registry checks of one [scene] value (also used for every swept value)."""
    if key in ("spacing", "dt", "mu", "inclusion_xy"):
        _limit(ctx, path, f"scene.{key}", value)
    elif key == "organ":
        from surgsim_envs.geometry.loaders import SURFACE_SUFFIXES, TET_SUFFIXES
        from surgsim_envs.geometry.organs import ORGANS

        if isinstance(value, str) and Path(value).suffix.lower() in SURFACE_SUFFIXES + TET_SUFFIXES:
            _check_file(ctx, path, value, ctx.folder, "organ mesh")   # a user's organ: a mesh file (data)
        else:
            known = ["block", *ORGANS]
            if value is not None and value not in known:
                raise ctx.error(path, f"unknown organ {value!r}; choose one of {', '.join(known)}, or name a mesh "
                                      f"file ({', '.join(SURFACE_SUFFIXES + TET_SUFFIXES)}) next to the scenario")
    elif key == "model":
        from surgsim_envs.tissue import registry

        _check_registered(ctx, path, value, registry.names(), "tissue model")
    elif key == "material":
        from surgsim_envs.materials import PRESETS

        _check_registered(ctx, path, value, sorted(PRESETS), "material preset")


def check_env_kwargs(ctx: ValidationContext, path: tuple, task: str, env_kwargs: dict) -> None:
    """``env_kwargs`` must be fields of task ``task``'s own config class with values its
    ``validate()`` accepts (the checks ``gym.make`` runs, without building the scene), so a file
    that passes ``--check`` cannot fail on them at run time."""
    import gymnasium as gym

    spec = gym.registry[task]
    env_cls = spec.entry_point
    if isinstance(env_cls, str):
        from gymnasium.envs.registration import load_env_creator

        env_cls = load_env_creator(env_cls)
    config_cls = getattr(env_cls, "config_cls", None)
    if config_cls is None:
        if env_kwargs:
            raise ctx.error(path, f"task {task!r} takes no env_kwargs here (it has no config class); remove them")
        return
    kwargs = {**(spec.kwargs or {}), **env_kwargs}
    render_mode = kwargs.pop("render_mode", None)
    if render_mode not in (None, "rgb_array"):
        raise ctx.error(path + ("render_mode",), f"render_mode {render_mode!r}: a scenario runs headless; use "
                                                 "'rgb_array' or leave it out")
    names = {f.name for f in dataclasses.fields(config_cls)}
    unknown = sorted(set(kwargs) - names)
    if unknown:
        raise ctx.error(path + (unknown[0],), f"{unknown} are not fields of {task}'s {config_cls.__name__}; its fields: "
                                             f"{', '.join(sorted(names))}")
    try:
        config = dataclasses.replace(config_cls(), **kwargs)
        config.validate()
    except ConfigError as exc:
        key = next((k for k in kwargs if k in str(exc)), None)
        raise ctx.error(path + ((key,) if key else ()), str(exc)) from None
    except Exception as exc:  # noqa: BLE001 - a value the task's checks did not foresee: still refused here
        raise ctx.error(path, f"{task} cannot take these env_kwargs ({type(exc).__name__}: {exc})") from None


def _check_script(ctx: ValidationContext, path: tuple, file: Path) -> None:
    """A trajectory script must parse and describe a valid, bounded trajectory."""
    from surgsim_envs.haptics.scripted import TrajectorySpec
    from surgsim_envs.haptics.teleop import load_script

    try:
        spec = TrajectorySpec.from_dict(load_script(str(file)))
        seconds = float(spec.duration)
    except ConfigError as exc:
        raise ctx.error(path, str(exc)) from None
    if not math.isfinite(seconds) or seconds > MAX_RUN_DURATION:
        raise ctx.error(path, f"the trajectory lasts {seconds:g} s, more than the {MAX_RUN_DURATION:g} s limit of a run")


def _check_task_id(ctx: ValidationContext, path: tuple, task: str) -> None:
    try:
        import gymnasium as gym

        import surgsim_envs.envs  # noqa: F401  (registers the SurgSim tasks)
    except ImportError as exc:
        raise ctx.error(path, f"task {task!r} needs gymnasium ({exc}); pip install gymnasium") from None
    if task not in gym.registry:
        ours = sorted(k for k in gym.registry if k.startswith("SurgSim/"))
        raise ctx.error(path, f"unknown task id {task!r}; registered SurgSim tasks: {', '.join(ours)}")


def _check_phase_values(ctx: ValidationContext, path: tuple, phase) -> None:
    """Range checks of a phase's physical values (by field name, see LIMITS)."""
    for f in dataclasses.fields(phase):
        rule = f"phase.{f.name}"
        if rule in LIMITS:
            _limit(ctx, path + (f.name,), rule, getattr(phase, f.name))
    grid = getattr(phase, "grid", None)
    if grid is not None and grid[0] * grid[1] > MAX_GRID_PRESSES:
        raise ctx.error(path + ("grid",), f"{list(grid)} asks for {grid[0] * grid[1]} presses; at most "
                                          f"{MAX_GRID_PRESSES}")


#: most levels of nested arrays/tables a scenario value may have (a scenario needs 3-4)
MAX_NESTING = 16


def _nesting_depth(value, limit: int = MAX_NESTING + 1) -> int:
    """Depth of nested lists/dicts in ``value``, counted iteratively and capped at ``limit``."""
    deepest, stack = 0, [(value, 0)]
    while stack:
        v, d = stack.pop()
        deepest = max(deepest, d)
        if deepest >= limit:
            return deepest
        if isinstance(v, dict):
            stack.extend((x, d + 1) for x in v.values())
        elif isinstance(v, list):
            stack.extend((x, d + 1) for x in v)
    return deepest


def _short(value, limit: int = 80) -> str:
    """``repr(value)`` cut to ``limit`` characters, for error messages."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."
