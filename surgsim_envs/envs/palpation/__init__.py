"""``SurgSim/Palpation-v0``: find a hidden stiff inclusion in a tissue slab with a probe
(:mod:`.env`); settings in :mod:`.config`, term functions in :mod:`.terms`, the scripted expert in
:mod:`.expert`."""

from surgsim_envs.envs.palpation.config import (MAX_TASK_NODES, RIGID_CONTACT_CLEARANCE, PalpationConfig,
                                               check_slab_size)
from surgsim_envs.envs.palpation.env import PalpationEnv
from surgsim_envs.envs.palpation.expert import palpation_expert
from surgsim_envs.envs.palpation.terms import (damage_penalty, indentation_depth, is_new_site,
                                              localisation_error, localisation_reward, map_cell, stiffness_estimate,
                                              stiffness_map, stiffness_weighted_estimate)

__all__ = ["PalpationConfig", "PalpationEnv", "palpation_expert", "check_slab_size", "MAX_TASK_NODES",
           "RIGID_CONTACT_CLEARANCE", "damage_penalty", "indentation_depth", "is_new_site",
           "localisation_error", "localisation_reward", "map_cell", "stiffness_estimate", "stiffness_map",
           "stiffness_weighted_estimate"]
