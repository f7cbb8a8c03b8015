"""Registry of tissue models: built-ins plus third-party models via entry points.

A third-party package registers a model class (a :class:`TissueModel` subclass) with::

    [project.entry-points."surgsim_envs.tissue_models"]
    my_model = "my_pkg.my_module:MyModel"
"""

from __future__ import annotations

import importlib
from importlib import metadata
from typing import Any, Mapping

from surgsim_envs.errors import ConfigError

ENTRY_POINT_GROUP = "surgsim_envs.tissue_models"

#: built-in models: name -> "module:Class" (imported lazily)
BUILTIN_MODELS: dict[str, str] = {
    "mass_spring": "surgsim_envs.tissue.mass_spring:MassSpringModel",
    "fem": "surgsim_envs.tissue.fem:TetFEMModel",
    "diffusion": "surgsim_envs.tissue.diffusion:DiffusionModel",
    "fractional": "surgsim_envs.tissue.fractional:FractionalTetModel",
    "mass_spring_calibrated": "surgsim_envs.tissue.calibrated_mass_spring:CalibratedMassSpringModel",
    "neo_hookean": "surgsim_envs.tissue.neo_hookean:NeoHookeanModel",
    "layered": "surgsim_envs.tissue.layered:LayeredModel",
    "fem_static": "surgsim_envs.tissue.fem_static:QuasiStaticFEMModel",
    "fem_hex": "surgsim_envs.tissue.fem_hex:HexStaticModel",
}

_registry: dict[str, Any] = {}
_entry_points_loaded = False


def register(name: str, target: Any, *, overwrite: bool = False) -> None:
    """Register a model class (or "module:Class" string) under ``name``."""
    if not overwrite and (name in _registry or name in BUILTIN_MODELS):
        raise ConfigError(f"tissue model {name!r} is already registered; pass overwrite=True to replace it")
    _registry[name] = target


def _load_entry_points() -> None:
    global _entry_points_loaded
    if _entry_points_loaded:
        return
    _entry_points_loaded = True
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        _registry.setdefault(ep.name, ep)


def _resolve(target: Any):
    if isinstance(target, str):
        module, _, attr = target.partition(":")
        return getattr(importlib.import_module(module), attr)
    if isinstance(target, metadata.EntryPoint):
        return target.load()
    return target


def names() -> list[str]:
    """Registered model names (built-ins first, then plugins)."""
    _load_entry_points()
    return list(BUILTIN_MODELS) + [n for n in _registry if n not in BUILTIN_MODELS]


def get(name: str):
    """The model class registered as ``name``."""
    _load_entry_points()
    if not isinstance(name, str):
        raise ConfigError(f"tissue model name must be a string, got {type(name).__name__}; registered models: {names()}")
    target = _registry.get(name, BUILTIN_MODELS.get(name))
    if target is None:
        raise ConfigError(f"unknown tissue model {name!r}; registered models: {names()}. "
                          "Third-party models register under the entry-point group 'surgsim_envs.tissue_models'.")
    return _resolve(target)


def describe() -> dict[str, str]:
    """{name: one-line summary} of every registered model."""
    out = {}
    for n in names():
        try:
            out[n] = getattr(get(n), "summary", "") or "(no summary)"
        except Exception as exc:  # a broken plugin must not hide the others
            out[n] = f"(failed to load: {exc})"
    return out


def make(name: str, volume, material: Any = "liver", **options):
    """Build tissue model ``name`` on ``volume`` (a Volume, a registered organ name or a mesh path
    for :func:`surgsim_envs.geometry.organ_volume`, with ``spacing`` / ``units`` in options) with ``material``
    (Material, preset name or dict). Remaining options go to the model's constructor."""
    cls = get(name)
    from surgsim_envs.geometry import Volume

    if not isinstance(volume, Volume):   # a registered organ name or a mesh path
        from surgsim_envs.geometry import organ_volume

        geo_opts = {k: options.pop(k) for k in ("spacing", "units") if k in options}
        volume = organ_volume(volume, **geo_opts)
    return cls(volume, material, **options)
