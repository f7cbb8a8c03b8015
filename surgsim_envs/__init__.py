"""surgsim_envs: MuJoCo-based surgical training environments with soft-tissue deformation plugins.

The Gymnasium tasks (``SurgSim/Palpation-v0``, ``SurgSim/Grasp-v0``, ``SurgSim/Slippage-v0``) are
registered as soon as Gymnasium is imported (before or after this package): importing
:mod:`surgsim_envs` itself loads neither Gymnasium nor MuJoCo, so ``import surgsim_envs.tissue``
stays a numpy + numba import (tests/test_layering.py). Tissue physics lives in
:mod:`surgsim_envs.tissue`, geometry in :mod:`surgsim_envs.geometry`, MuJoCo scenes in
:mod:`surgsim_envs.scene`. All quantities are SI (m, kg, s, N, Pa).
"""

import importlib.abc
import importlib.util
import sys

__version__ = "0.1.0"

from surgsim_envs.numba_cache import invalidate_stale_caches  # noqa: E402  (os/hashlib only)
from surgsim_envs.numba_cache_lock import install as _lock_numba_cache  # noqa: E402  (no numba import)

_lock_numba_cache()         # processes compiling at once share numba's cache safely
invalidate_stale_caches()   # numba checks only a kernel's own file: drop caches of changed kernels

from surgsim_envs.asset_files import assets_path  # noqa: E402  (pathlib only)


def _register_envs() -> None:
    try:
        from surgsim_envs.envs import register_envs
    except ImportError:  # envs not built yet, or gymnasium/mujoco missing
        return
    register_envs()


class _RegisterWhenGymnasiumLoads(importlib.abc.MetaPathFinder):
    """Import hook: once ``gymnasium`` has been imported, register the tasks (one shot)."""

    def find_spec(self, name, path=None, target=None):
        if name != "gymnasium":
            return None
        if self in sys.meta_path:
            sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
            return spec
        loader = spec.loader
        exec_module = loader.exec_module

        def exec_then_register(module):
            exec_module(module)
            _register_envs()

        loader.exec_module = exec_then_register
        return spec


if "gymnasium" in sys.modules:
    _register_envs()
elif not any(isinstance(f, _RegisterWhenGymnasiumLoads) for f in sys.meta_path):
    sys.meta_path.insert(0, _RegisterWhenGymnasiumLoads())
