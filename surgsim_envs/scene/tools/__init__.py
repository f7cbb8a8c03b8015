"""Tool kinds as plugins: one module per kind, one registration each.

A tool kind is a module with ``KIND`` (its name), ``build(spec, cfg) -> ToolSpec`` (adds it to a
:class:`mujoco.MjSpec`; the returned ToolSpec subclass carries the kind's commands and readouts)
and ``validate(cfg)`` (ConfigError naming the bad field), registered here against its config
dataclass. ``SceneConfig.tools`` is a list of such configs; the builder and the step loop look
the kind up by the config's type and never branch on a kind's name.

>>> from surgsim_envs.scene.tools import register_tool
>>> register_tool(ScissorsConfig, "my_package.scissors")      # doctest: +SKIP
"""

from __future__ import annotations

import importlib
from types import ModuleType

from surgsim_envs.errors import ConfigError
from surgsim_envs.scene.config import GrasperConfig, ProbeConfig
from surgsim_envs.scene.tools import proxy
from surgsim_envs.scene.tools.base import TOOL_CONAFFINITY, TOOL_CONTYPE, ToolSpec

#: tool config class -> module path of its kind
_KINDS: dict[type, str] = {}


def register_tool(config_cls: type, module: str) -> None:
    """Register the tool kind in ``module`` (dotted path) for configs of type ``config_cls``."""
    _KINDS[config_cls] = module


def tool_kind(cfg) -> ModuleType:
    """The module of the kind of tool config ``cfg`` (ConfigError listing the known configs)."""
    module = _KINDS.get(type(cfg))
    if module is None:
        raise ConfigError(f"{type(cfg).__name__} is not a registered tool config; known: "
                          f"{sorted(c.__name__ for c in _KINDS)} (register_tool(ConfigClass, 'module'))")
    return importlib.import_module(module)


def build_tool(spec, cfg) -> ToolSpec:
    """Add the tool of config ``cfg`` to ``spec``; return its ToolSpec."""
    return tool_kind(cfg).build(spec, cfg)


register_tool(ProbeConfig, "surgsim_envs.scene.tools.probe")
register_tool(GrasperConfig, "surgsim_envs.scene.tools.grasper")


def add_haptic_proxy(spec, cfg, tool: ToolSpec) -> None:
    """Add a mocap proxy welded to ``tool`` (see :mod:`surgsim_envs.scene.tools.proxy`)."""
    proxy.build(spec, cfg, tool)


__all__ = ["ToolSpec", "TOOL_CONTYPE", "TOOL_CONAFFINITY", "register_tool", "tool_kind", "build_tool",
           "add_haptic_proxy"]
