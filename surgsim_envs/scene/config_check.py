"""Checks of a whole :class:`~surgsim_envs.scene.config.SceneConfig` before a scene is built.

:func:`validate_scene_config` raises :class:`~surgsim_envs.errors.ConfigError` naming the first bad
value and its fix; the builders call it. It sits above the config dataclasses and the tool kinds
(each kind validates its own config), so neither of those imports the other's checks.
"""

from __future__ import annotations

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError
from surgsim_envs.scene.config import SceneConfig, TissueConfig, validate_step, vec
from surgsim_envs.scene.tools import tool_kind
from surgsim_envs.tissue.resolution import check_resolution


def validate_tissue_resolution(t: TissueConfig) -> None:
    """Check ``resolution``, ``model="auto"`` and the auto-selection limits of one tissue."""
    check_resolution(t.resolution, f"tissue '{t.name}' resolution")
    if t.model == "auto" and t.resolution != "auto":
        raise ConfigError(f"tissue '{t.name}': model='auto' needs resolution='auto' (the table picks both); "
                          "or name a model such as 'mass_spring' or 'fem'")
    if t.resolution == "auto":
        validate.positive(t.error_tolerance, f"tissue '{t.name}' error_tolerance", fix="a fraction, e.g. 0.1 for 10 %")
        validate.positive(t.step_budget_us, f"tissue '{t.name}' step_budget_us",
                          fix="microseconds of compute per simulated millisecond, e.g. 1000")
        if not isinstance(t.accuracy_scene, str) or not t.accuracy_scene:
            raise ConfigError(f"tissue '{t.name}' accuracy_scene={t.accuracy_scene!r}; give a benchmark scene "
                              "name such as 'indent'")


def validate_scene_config(cfg: SceneConfig) -> None:
    """Check a SceneConfig; raise ConfigError naming the first bad value and how to fix it."""
    if not isinstance(cfg, SceneConfig):
        raise ConfigError(f"expected a SceneConfig, got {type(cfg).__name__}")
    validate_step(cfg.dt, cfg.substeps)
    vec(cfg.gravity, 3, "gravity")
    for flag in ("floor", "rigid_contacts"):
        if not isinstance(getattr(cfg, flag), bool):
            raise ConfigError(f"scene '{cfg.name}' {flag} must be True or False, got {getattr(cfg, flag)!r}")
    names: set[str] = set()
    for group in (cfg.tissues, cfg.tools, cfg.proxies, cfg.cameras):
        for item in group:
            if not isinstance(item.name, str) or not item.name:
                raise ConfigError(f"every scene object needs a non-empty name, got {item.name!r}")
            if item.name in names:
                raise ConfigError(f"duplicate scene object name {item.name!r}; names of tissues, tools, proxies "
                                  "and cameras must be unique")
            names.add(item.name)
    for t in cfg.tissues:
        validate_tissue_resolution(t)
        if t.spacing is not None:
            validate.positive(t.spacing, f"tissue '{t.name}' spacing", unit="m",
                              fix="try 0.005 (5 mm), or None for the organ's default")
        vec(t.position, 3, f"tissue '{t.name}' position")
        vec(t.euler, 3, f"tissue '{t.name}' euler")
        vec(t.gravity, 3, f"tissue '{t.name}' gravity")
        vec(t.rgba, 4, f"tissue '{t.name}' rgba")
    for t in cfg.tools:
        tool_kind(t).validate(t)
    tools = {p.name: p for p in cfg.tools}
    driven = set()
    for h in cfg.proxies:
        if h.tool not in tools:
            raise ConfigError(f"haptic proxy '{h.name}' drives tool {h.tool!r}, which does not exist; "
                              f"tools in this scene: {sorted(tools)}")
        if tools[h.tool].drive != "proxy":
            raise ConfigError(f"haptic proxy '{h.name}': tool '{h.tool}' has drive={tools[h.tool].drive!r}; "
                              "set its drive='proxy'")
        if h.tool in driven:
            raise ConfigError(f"tool '{h.tool}' is driven by two haptic proxies; give each tool at most one")
        driven.add(h.tool)
        validate.positive(h.timeconst, f"haptic proxy '{h.name}' timeconst", unit="s", fix="e.g. 0.01 s")
        validate.positive(h.dampratio, f"haptic proxy '{h.name}' dampratio", fix="1 is critical damping")
    for t in tools.values():
        if t.drive == "proxy" and t.name not in driven:
            raise ConfigError(f"tool '{t.name}' has drive='proxy' but no HapticProxyConfig(tool='{t.name}') drives it")
    for c in cfg.cameras:
        vec(c.position, 3, f"camera '{c.name}' position")
        vec(c.target, 3, f"camera '{c.name}' target")
