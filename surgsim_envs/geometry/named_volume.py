"""Named volumes: the boxes "block" and "slab", or a procedural organ by name."""

from __future__ import annotations

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry import organs
from surgsim_envs.geometry.box import box_volume
from surgsim_envs.geometry.organs import ORGANS
from surgsim_envs.geometry.volume import Volume


def make_volume(name: str, spacing: float | None = None, **kwargs) -> Volume:
    """A named procedural volume: "block", "slab" (boxes centred at the origin, default spacing
    5 mm) or an organ of :mod:`surgsim_envs.geometry.organs` ("slab_inclusion", "spleen",
    "liver_lobe"; organs rest on z = 0). ``spacing`` in m."""
    if name in ("block", "slab"):
        size = kwargs.pop("size", (0.08, 0.08, 0.03) if name == "block" else (0.1, 0.1, 0.02))
        return box_volume(size, spacing or 0.005, name=name, **kwargs)
    if not isinstance(name, str):
        raise ConfigError(f"volume name must be a string, got {name!r}; known: {['block', *ORGANS]}")
    return organs.make_volume(name, spacing=spacing, **kwargs)
