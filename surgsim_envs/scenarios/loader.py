"""Reading a scenario: TOML text or a file -> a validated :class:`~surgsim_envs.scenarios.schema.Scenario`.
The format and the rules it checks are in :mod:`surgsim_envs.scenarios.schema`; the phase types
and criteria it builds come from :mod:`~surgsim_envs.scenarios.phases` and
:mod:`~surgsim_envs.scenarios.scoring`, which build on the schema's checks.
"""

from __future__ import annotations

import dataclasses
import re
import typing
from pathlib import Path

from surgsim_envs.errors import ConfigError
from surgsim_envs.scenarios.phases import build_phase, check_phase_order
from surgsim_envs.scenarios.schema import (CriterionSpec, KeyLocator, MAX_FILE_BYTES, MAX_NESTING,
                                           MAX_RUN_DURATION, NAME_PATTERN, PolicySpec, SCENES, Scenario,
                                           ScenarioMeta, SceneOverrides, ScoringSpec, TraineeSpec,
                                           ValidationContext, _TOP, _check_file, _check_phase_values,
                                           _check_scene_value, _check_script, _check_task_id, _check_type,
                                           _limit, _nesting_depth, build_dataclass, check_env_kwargs,
                                           check_policy, resolve_data_file, validate_driver)
from surgsim_envs.scenarios.scoring import CRITERIA

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - python < 3.11
    import tomli as tomllib  # type: ignore[no-redef]


def parse_scenario(data: dict, source: str = "<scenario>", text: str | None = None, folder: Path | None = None,
                   allow_code: bool = False) -> Scenario:
    """Validate a parsed TOML document and build a :class:`Scenario` (ConfigError on any problem).

    ``folder``: where relative file names point (the scenario file's folder); ``allow_code``:
    accept code-loading policies (see :mod:`surgsim_envs.scenarios.policies`)."""
    ctx = ValidationContext(source, KeyLocator(text), folder)
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: a scenario must be a TOML document (a table), got {type(data).__name__}")
    if _nesting_depth(data) > MAX_NESTING:
        raise ConfigError(f"{source}: values nested too deeply (more than {MAX_NESTING} levels of arrays/tables); "
                          "a scenario needs at most a few levels")
    for key in data:
        if key not in _TOP:
            raise ctx.error((key,), f"unknown top-level table {key!r}; allowed: {', '.join(_TOP)}")
    if "scenario" not in data:
        raise ctx.error(("scenario",), "missing the [scenario] table (it needs at least name = \"...\")")
    meta = build_dataclass(ScenarioMeta, data["scenario"], ("scenario",), ctx)
    if not re.fullmatch(NAME_PATTERN, meta.name):
        raise ctx.error(("scenario", "name"), f"give a name of letters, digits, '_', '-' or '.' (not starting with "
                                              f"'.', at most 100 characters; it names the output folder), got "
                                              f"{meta.name!r}")
    if meta.task and meta.scene:
        raise ctx.error(("scenario", "task"), f"give either scene = ... (scripted phases) or task = ... (a Gymnasium "
                                              f"policy rollout), not both (scene={meta.scene!r}, task={meta.task!r})")
    if not meta.task and meta.scene not in SCENES:
        raise ctx.error(("scenario", "scene"), f"unknown scene {meta.scene!r}; choose one of {', '.join(SCENES)} "
                                               "(or set task = \"SurgSim/...-v0\" for a policy rollout)")
    for key in ("sample_period", "duration_scale", "seed"):
        _limit(ctx, ("scenario", key), f"scenario.{key}", getattr(meta, key))
    if meta.task:
        _check_task_id(ctx, ("scenario", "task"), meta.task)
    scene = build_dataclass(SceneOverrides, data.get("scene", {}), ("scene",), ctx)
    for f in dataclasses.fields(SceneOverrides):
        _check_scene_value(ctx, ("scene", f.name), f.name, getattr(scene, f.name))
    trainee = build_dataclass(TraineeSpec, data.get("trainee", {}), ("trainee",), ctx)
    drivers = dict(folder=folder, allow_code=allow_code, trusted=False, check_files=True)
    validate_driver(ctx, ("trainee",), trainee.driver, trainee.device, trainee.policy, **drivers)
    _limit(ctx, ("trainee", "tremor"), "trainee.tremor", trainee.tremor)
    if trainee.script:
        _check_file(ctx, ("trainee", "script"), trainee.script, folder, "trajectory script")
        _check_script(ctx, ("trainee", "script"), resolve_data_file(trainee.script, folder))

    scoring_tab = data.get("scoring", {})
    scoring = build_dataclass(ScoringSpec, scoring_tab, ("scoring",), ctx, skip=("criteria",))
    _limit(ctx, ("scoring", "safety_limit"), "scoring.safety_limit", scoring.safety_limit)
    crit_tab = scoring_tab.get("criteria", {}) if isinstance(scoring_tab, dict) else {}
    if not isinstance(crit_tab, dict):
        raise ctx.error(("scoring", "criteria"), f"expected a table of criteria, got {crit_tab!r}")
    for name, tab in crit_tab.items():
        if name not in CRITERIA:
            raise ctx.error(("scoring", "criteria", name), f"unknown criterion {name!r}; choose from "
                                                           f"{', '.join(CRITERIA)}")
        crit = build_dataclass(CriterionSpec, tab, ("scoring", "criteria", name), ctx)
        for key in ("weight", "target", "limit"):
            _limit(ctx, ("scoring", "criteria", name, key), f"criterion.{key}", getattr(crit, key))
        if name != "completion" and not crit.limit > crit.target:
            raise ctx.error(("scoring", "criteria", name, "limit"),
                            f"limit ({crit.limit}) must be greater than target ({crit.target})")
        scoring.criteria[name] = crit

    sweep = data.get("sweep", {})
    if not isinstance(sweep, dict):
        raise ctx.error(("sweep",), f"expected a table like mu = [0.6, 0.8, 1.0], got {sweep!r}")
    allowed = [f.name for f in dataclasses.fields(SceneOverrides)]
    lengths = set()
    for key, values in sweep.items():
        if key not in allowed:
            raise ctx.error(("sweep", key), f"cannot sweep {key!r}; sweepable [scene] keys: {', '.join(allowed)}")
        if not isinstance(values, list) or not values:
            raise ctx.error(("sweep", key), f"expected a non-empty array of values, got {values!r}")
        hint = typing.get_type_hints(SceneOverrides)[key]
        if len(values) > 100:
            raise ctx.error(("sweep", key), f"{len(values)} values: at most 100 runs per sweep")
        for i, v in enumerate(values):
            _check_scene_value(ctx, ("sweep", key, i), key, _check_type(v, hint, ("sweep", key, i), ctx))
        lengths.add(len(values))
    if len(lengths) > 1:
        raise ctx.error(("sweep",), f"all swept arrays must have the same length, got lengths {sorted(lengths)}")

    policy = None
    if "policy" in data:
        if not meta.task:
            raise ctx.error(("policy",), "a [policy] table needs scenario.task (a Gymnasium task id)")
        policy = build_dataclass(PolicySpec, data["policy"], ("policy",), ctx)
        if not policy.file:
            raise ctx.error(("policy", "file"), "give the policy: a .npz data policy, 'builtin:NAME' or (with "
                                                "--allow-code) 'file.py:function'")
        check_policy(ctx, ("policy", "file"), policy.file, folder, allow_code, trusted=False)
        _limit(ctx, ("policy", "episodes"), "policy.episodes", policy.episodes)
        _limit(ctx, ("policy", "max_steps"), "policy.max_steps", policy.max_steps)
        check_env_kwargs(ctx, ("policy", "env_kwargs"), meta.task, policy.env_kwargs)
    elif meta.task:
        raise ctx.error(("scenario", "task"), "a task rollout needs a [policy] table with file = '...'")

    phases_tab = data.get("phases", [])
    if meta.task:
        if phases_tab:
            raise ctx.error(("phases",), "a Gymnasium task rollout takes no [[phases]]; the policy drives the task")
    else:
        if not isinstance(phases_tab, list) or not phases_tab:
            raise ctx.error(("phases",), "a scenario needs at least one [[phases]] table (e.g. type = \"hold\")")
    if len(phases_tab) > 1000:
        raise ctx.error(("phases",), f"{len(phases_tab)} phases: at most 1000")
    phases = []
    for i, tab in enumerate(phases_tab):
        if isinstance(tab, dict) and not isinstance(tab.get("type"), str):
            raise ctx.error(("phases", i, "type"), f"give the phase type as a string, got {tab.get('type')!r}")
        phase = build_phase(tab, ("phases", i), ctx, trainee)
        _check_phase_values(ctx, ("phases", i), phase)
        validate_driver(ctx, ("phases", i), phase.driver, phase.device, phase.policy, **drivers)
        phases.append(phase)
    if phases:
        check_phase_order(phases, meta.scene, ctx)
    sc = Scenario(meta=meta, scene=scene, trainee=trainee, phases=phases, scoring=scoring, sweep=dict(sweep),
                  policy=policy, source=None, folder=folder, allow_code=allow_code)
    if sc.run_duration() > MAX_RUN_DURATION:
        raise ctx.error(("phases",), f"one run lasts {sc.run_duration():g} s of simulated time (phase durations x "
                                     f"duration_scale), more than the {MAX_RUN_DURATION:g} s limit")
    return sc


def loads_scenario(text: str, source: str = "<string>", folder: Path | None = None,
                   allow_code: bool = False) -> Scenario:
    """Parse and validate scenario TOML ``text`` (relative file names resolve against ``folder``)."""
    if not isinstance(text, str):
        raise ConfigError(f"{source}: scenario text must be a string, got {type(text).__name__}")
    if len(text) > MAX_FILE_BYTES:
        raise ConfigError(f"{source}: {len(text)} characters; a scenario file is at most {MAX_FILE_BYTES} "
                          "(move data into separate files)")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: not valid TOML: {exc}") from None
    except RecursionError:
        raise ConfigError(f"{source}: arrays or tables nested too deeply to parse; a scenario needs at most a few "
                          "levels of nesting") from None
    try:
        return parse_scenario(data, source, text, folder=folder, allow_code=allow_code)
    except RecursionError:
        raise ConfigError(f"{source}: values nested too deeply; a scenario needs at most a few levels") from None


def load_scenario(path, allow_code: bool = False) -> Scenario:
    """Load and validate the scenario file ``path`` (.toml); ``allow_code`` accepts code-loading
    policies (``--allow-code``)."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"scenario file {str(path)!r} not found; give a path such as tasks/spleen_grasp_and_retract.toml")
    if p.stat().st_size > MAX_FILE_BYTES:
        raise ConfigError(f"scenario file {str(p)!r} is {p.stat().st_size} bytes; at most {MAX_FILE_BYTES}")
    try:
        text = p.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"scenario file {str(p)!r} cannot be read as UTF-8 text ({exc})") from None
    sc = loads_scenario(text, str(p), folder=p.parent, allow_code=allow_code)
    sc.source = p
    return sc
