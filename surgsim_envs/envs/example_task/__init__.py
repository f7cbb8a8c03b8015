"""``SurgSim/ExamplePress-v0``, the worked example of adding a task (docs/adding_a_task.md): this
folder (config, env, terms, expert) plus one :class:`~surgsim_envs.envs.registry.TaskSpec`,
:data:`SPEC`. It is not registered by default: ``register(SPEC)`` adds it (the test does); to ship
a task, put its spec in :data:`surgsim_envs.envs.registry.TASKS` instead."""

from surgsim_envs.envs.example_task.config import ExamplePressConfig
from surgsim_envs.envs.example_task.env import ExamplePressEnv
from surgsim_envs.envs.example_task.expert import press_to_force_expert
from surgsim_envs.envs.example_task.terms import force_error_penalty
from surgsim_envs.envs.registry import ForceTolerance, TaskSpec

#: the task's one registry entry
SPEC = TaskSpec(
    "SurgSim/ExamplePress-v0", "surgsim_envs.envs.example_task:ExamplePressEnv",
    "surgsim_envs.envs.example_task:ExamplePressConfig", scene="palpation", tool="probe", model="mass_spring",
    force_tolerance=ForceTolerance(0.05, why="the reward is the relative force error: a 5 % model error is a "
                                             "5 % floor under the error the agent can reach"),
    max_episode_steps=50, quick={"episode_seconds": 0.2},
    expert="surgsim_envs.envs.example_task:press_to_force_expert")

__all__ = ["SPEC", "ExamplePressConfig", "ExamplePressEnv", "press_to_force_expert", "force_error_penalty"]
