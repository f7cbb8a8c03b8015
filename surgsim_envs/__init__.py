"""surgsim_envs: MuJoCo-based surgical training environments with soft-tissue deformation plugins.

Importing the package registers the Gymnasium tasks (``SurgSim/Palpation-v0``, ``SurgSim/Grasp-v0``,
``SurgSim/Slippage-v0``) when the ``envs`` subpackage is present. Tissue physics lives in
:mod:`surgsim_envs.tissue`, geometry in :mod:`surgsim_envs.geometry`, MuJoCo scenes in
:mod:`surgsim_envs.scene`. All quantities are SI (m, kg, s, N, Pa).
"""

__version__ = "0.1.0"


def _register_envs() -> None:
    try:
        from surgsim_envs.envs import register_envs
    except ImportError:  # envs not built yet, or gymnasium missing
        return
    register_envs()


_register_envs()
