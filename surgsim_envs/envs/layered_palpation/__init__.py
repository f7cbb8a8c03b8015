"""``SurgSim/LayeredPalpation-v0``: find a stiff nodule under the skin of an abdominal wall by pressing
(:mod:`.env`, quasi-static: one equilibrium solve per press); settings in :mod:`.config`, the
MuJoCo picture of a press for rendering and dm_control in :mod:`.scene`."""

from surgsim_envs.envs.layered_palpation.config import (CAMERAS, MAX_DEPTH_LIMIT, MAX_NODES, SIZE_RANGE,
                                                       SPACING_RANGE, LayeredPalpationConfig)
from surgsim_envs.envs.layered_palpation.env import LayeredPalpationEnv

__all__ = ["LayeredPalpationConfig", "LayeredPalpationEnv", "CAMERAS", "MAX_DEPTH_LIMIT", "MAX_NODES", "SIZE_RANGE",
           "SPACING_RANGE"]
