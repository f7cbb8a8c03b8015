"""``SurgSim/PalpationPress-v0``: Palpation-v0 with one decision per press (:mod:`.env`); settings in
:mod:`.config`, term functions in :mod:`.terms`, the scripted expert in :mod:`.expert`."""

from surgsim_envs.envs.palpation_press.config import MAX_PRESS_STEPS, MAX_PRESSES, PalpationPressConfig
from surgsim_envs.envs.palpation_press.env import PalpationPressEnv
from surgsim_envs.envs.palpation_press.expert import press_expert
from surgsim_envs.envs.palpation_press.terms import cell_centre, raster_order

__all__ = ["PalpationPressConfig", "PalpationPressEnv", "press_expert", "cell_centre", "raster_order",
           "MAX_PRESS_STEPS", "MAX_PRESSES"]
