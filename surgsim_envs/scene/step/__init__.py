"""The physics step of a scene: the per-substep kernels (:mod:`.kernels`), the compiled substep loop
and its runner (:mod:`.loop`), the choice of loop per scene (:mod:`.compiled`) and MuJoCo's C step
functions callable from compiled code (:mod:`.mujoco_native`). The Python reference loop and the
commands and readouts stay on :class:`~surgsim_envs.scene.simulation.Simulation`."""
