"""Geometry: volumes, procedural organs, mesh loading and volumetric discretisation (no MuJoCo)."""

from surgsim_envs.geometry.box import box_volume, lattice_tets
from surgsim_envs.geometry.volume import Volume, boundary_triangles, tet_signed_volumes

__all__ = ["Volume", "box_volume", "lattice_tets", "boundary_triangles", "tet_signed_volumes", "make_volume"]


def make_volume(name: str, spacing: float | None = None, **kwargs) -> Volume:
    """A named procedural volume ("block", "slab", ...; organs once geometry.organs exists)."""
    from surgsim_envs.errors import ConfigError

    if name in ("block", "slab"):
        size = kwargs.pop("size", (0.08, 0.08, 0.03) if name == "block" else (0.1, 0.1, 0.02))
        return box_volume(size, spacing or 0.005, name=name, **kwargs)
    try:
        from surgsim_envs.geometry import organs
    except ImportError:
        raise ConfigError(f"unknown volume {name!r}; available: ['block', 'slab']") from None
    return organs.make_volume(name, spacing=spacing, **kwargs)
