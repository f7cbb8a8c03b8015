"""The shared-memory multi-process vector env: what ``gym.make_vec(task, num_envs=n)`` returns for
every SurgSim task (:class:`~surgsim_envs.vector.env.SurgSimVectorEnv`).

Modules: ``env`` (the main process side), ``worker`` (the worker process), ``ipc`` (the
shared-memory layout and the pipe protocol), ``info`` (numeric info entries through shared
memory), ``parent`` (workers exit when the main process dies). It steps envs made by
``gymnasium.make``, so it imports nothing from :mod:`surgsim_envs.envs`.
"""

from surgsim_envs.vector.env import SurgSimVectorEnv

__all__ = ["SurgSimVectorEnv"]
