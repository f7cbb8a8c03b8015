"""Run a callback once a module has been imported, without importing it now.

The package registers its Gymnasium tasks when ``gymnasium`` loads and locks numba's cache files
when ``numba.core.caching`` loads (:mod:`surgsim_envs.numba_cache_lock`), whichever is imported
first, so that ``import surgsim_envs`` itself imports neither. :func:`after_import` calls
``callback(module)`` at once when ``name`` is already in ``sys.modules``, and otherwise inserts a
one-shot finder at the front of ``sys.meta_path`` that wraps the module's loader: the callback
runs right after the module's code, before the import statement returns.
"""

from __future__ import annotations

import importlib.abc
import importlib.util
import sys
from typing import Callable


class _AfterImport(importlib.abc.MetaPathFinder):
    """One-shot finder: when ``name`` is imported, run ``callback(module)`` after its code."""

    def __init__(self, name: str, callback: Callable):
        self.name, self.callback = name, callback

    def find_spec(self, name, path=None, target=None):
        if name != self.name:
            return None
        if self in sys.meta_path:
            sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
            return spec
        loader, callback = spec.loader, self.callback
        exec_module = loader.exec_module

        def exec_then_call(module):
            exec_module(module)
            callback(module)

        loader.exec_module = exec_then_call
        return spec


def after_import(name: str, callback: Callable) -> None:
    """``callback(module)`` once module ``name`` is imported: now if it is loaded, else right after
    its first import (at most one pending callback per name and callback)."""
    if name in sys.modules:
        callback(sys.modules[name])
        return
    if not any(isinstance(f, _AfterImport) and (f.name, f.callback) == (name, callback) for f in sys.meta_path):
        sys.meta_path.insert(0, _AfterImport(name, callback))
