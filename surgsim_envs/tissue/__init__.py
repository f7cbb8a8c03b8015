"""Soft-tissue physics: the model interface, materials, registry and models (numpy + numba only).

>>> from surgsim_envs import tissue, geometry
>>> vol = geometry.box_volume((0.06, 0.06, 0.02), spacing=0.005)
>>> model = tissue.make("mass_spring", vol, "liver")
>>> model.step(1e-3)
"""

from surgsim_envs.errors import TissueUnstableError
from surgsim_envs.tissue.base import TissueModel
from surgsim_envs.tissue.guard import StabilityGuard
from surgsim_envs.materials import PRESETS, Material, get_material
from surgsim_envs.tissue.registry import describe, get, make, names, register

__all__ = ["TissueModel", "TissueUnstableError", "StabilityGuard", "Material", "PRESETS", "get_material",
           "make", "register", "names", "get", "describe"]
