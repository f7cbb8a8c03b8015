"""``SurgSim/Grasp-v0``: close a three-jaw grasper on an organ tip and retract it to a target
(:mod:`.env`); settings in :mod:`.config`, the scripted expert in :mod:`.expert`. The grasp scene
shared with Slippage-v0 lives here too: the config fields and env part (:mod:`.scene`), the coarse
organ simulations (:mod:`.simulation`) and the grasp-state term functions (:mod:`.terms`)."""

from surgsim_envs.envs.grasp.config import GraspConfig
from surgsim_envs.envs.grasp.env import GraspEnv
from surgsim_envs.envs.grasp.expert import grasp_expert
from surgsim_envs.envs.grasp.scene import (MAX_SUBCYCLED_RIGID_DT, GraspSceneConfig, GraspSceneEnv,
                                          resolved_subcycles)
from surgsim_envs.envs.grasp.simulation import (MESH_SPACING, ORGAN_SPACING, build_grasp_simulation,
                                               check_grasp_organ)
from surgsim_envs.envs.grasp.terms import (SlipTracker, contact_nodes, contact_reward, excess_force_penalty,
                                          is_grasped, jaws_in_contact, record_progress, slip_fraction)

__all__ = ["GraspConfig", "GraspEnv", "grasp_expert", "GraspSceneConfig", "GraspSceneEnv", "MAX_SUBCYCLED_RIGID_DT",
           "resolved_subcycles", "ORGAN_SPACING", "MESH_SPACING", "build_grasp_simulation", "check_grasp_organ",
           "SlipTracker", "contact_nodes", "contact_reward", "excess_force_penalty", "is_grasped", "jaws_in_contact",
           "record_progress", "slip_fraction"]
