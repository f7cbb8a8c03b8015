"""``SurgSim/Slippage-v0``: hold a grasped organ against a ramping, varying pull with the least
squeeze (:mod:`.env`); settings in :mod:`.config`, term functions in :mod:`.terms`, the scripted
expert in :mod:`.expert`. The grasp scene is Grasp-v0's (:mod:`surgsim_envs.envs.grasp.scene`)."""

from surgsim_envs.envs.slippage.config import MAX_SETTLE_SECONDS, SlippageConfig
from surgsim_envs.envs.slippage.env import SlippageEnv
from surgsim_envs.envs.slippage.expert import slippage_expert
from surgsim_envs.envs.slippage.terms import (excess_squeeze_penalty, least_squeeze, no_pull, pull_force,
                                             slip_penalty)

__all__ = ["SlippageConfig", "SlippageEnv", "slippage_expert", "MAX_SETTLE_SECONDS", "excess_squeeze_penalty",
           "least_squeeze", "no_pull", "pull_force", "slip_penalty"]
