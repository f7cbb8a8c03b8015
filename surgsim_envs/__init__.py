"""surgsim_envs: MuJoCo-based surgical training environments with soft-tissue deformation plugins.

The Gymnasium tasks (``SurgSim/Palpation-v0``, ``SurgSim/Grasp-v0``, ``SurgSim/Slippage-v0``) are
registered as soon as Gymnasium is imported (before or after this package): importing
:mod:`surgsim_envs` itself loads neither Gymnasium nor MuJoCo, so ``import surgsim_envs.tissue``
stays a numpy + numba import (tests/test_layering.py). Tissue physics lives in
:mod:`surgsim_envs.tissue`, geometry in :mod:`surgsim_envs.geometry`, MuJoCo scenes in
:mod:`surgsim_envs.scene`. All quantities are SI (m, kg, s, N, Pa).
"""

__version__ = "0.1.0"

from surgsim_envs.after_import import after_import  # noqa: E402  (importlib only)
from surgsim_envs.numba_cache import invalidate_stale_caches  # noqa: E402  (os/hashlib only)
from surgsim_envs.numba_cache_lock import install as _lock_numba_cache  # noqa: E402  (no numba import)

_lock_numba_cache()         # processes compiling at once share numba's cache safely
invalidate_stale_caches()   # numba checks only a kernel's own file: drop caches of changed kernels

from surgsim_envs.asset_files import assets_path  # noqa: E402  (pathlib only)


def _register_envs(gymnasium_module=None) -> None:
    try:
        from surgsim_envs.envs import register_envs
    except ImportError:  # envs not built yet, or gymnasium/mujoco missing
        return
    register_envs()


after_import("gymnasium", _register_envs)      # the tasks register once Gymnasium is imported
