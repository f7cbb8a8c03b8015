"""Batched simulation on NVIDIA Warp devices: W copies of one task's scene stepped together.

Tissue state is flat per-world arrays (float64) stepped by Warp kernels; tools live in MuJoCo Warp.
Needs the ``[batch]`` extra (warp-lang, mujoco-warp); the same kernels run on Warp's CPU device
(tests, CI) and on CUDA. See docs/batch.md.

* :class:`~surgsim_envs.batch.simulation.BatchSimulation` - the physics of W worlds and their readouts;
* :class:`~surgsim_envs.batch.env.BatchedTaskEnv` - the base of the Gymnasium vector envs, with one
  module per task: :class:`~surgsim_envs.batch.palpation_env.BatchedPalpationEnv` and
  :class:`~surgsim_envs.batch.grasp_env.BatchedGraspEnv`,
  ``gym.make_vec("SurgSim/Grasp-v0", num_envs=N, vectorization_mode="vector_entry_point", device="cpu")``.
"""

from surgsim_envs.batch.backend import BatchUnavailableError, available, cuda_available

__all__ = ["BatchUnavailableError", "available", "cuda_available"]
