"""One numba cache for processes that compile at the same time.

numba (0.5x-0.6x) saves a compiled specialisation of a ``cache=True`` kernel in three steps: it
reads the function's index file, picks the first data-file number the index does not use, writes
the index, then the data file. Each write is atomic (a temporary file moved into place); the
sequence is not. Two processes that compile specialisations of one function at once both pick the
same number, and the index ends up naming one specialisation's key with the other's machine code:
the next process that loads that key runs code compiled for other argument types. On a cold
install any set of processes started together meets this (the workers of a parallel test run, the
subprocesses of an async vector env, a cluster's jobs on one shared install); a fresh clone's
parallel test run died of it with a segmentation fault inside a FEM kernel.

:func:`install` wraps numba's ``IndexDataCacheFile.save``, ``.load`` and ``.flush`` (public
methods of :mod:`numba.core.caching`) in one lock: a thread lock plus an ``flock`` on a lock file
per user in the temporary folder. A load then never sees an index whose data file is not written
yet, and two saves never pick the same number, so the processes share one cache and each kernel
is compiled once, by whichever process needs it first. The lock is held for the file operations
only (milliseconds), never during a compile. The package installs it lazily, when numba's caching
module is first imported, so ``import surgsim_envs`` still does not import numba.

Processes share the lock through the temporary folder (``tempfile.gettempdir()``, i.e. ``TMPDIR``):
two processes given different temporary folders do not exclude each other, and numba's own
behaviour returns between them. Where the lock cannot be taken (no ``fcntl``, an unwritable temporary folder, or a holder that
keeps it past :data:`TIMEOUT_S`) the cache works as numba's own, unlocked; nothing fails or hangs.
``SURGSIM_NUMBA_CACHE_LOCK=0`` turns it off.
"""

from __future__ import annotations

import contextlib
import functools
import os
import sys
import tempfile
import threading
import time

from surgsim_envs.after_import import after_import

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: the thread lock only
    fcntl = None

CACHING_MODULE = "numba.core.caching"
LOCKED_METHODS = ("save", "load", "flush")
TIMEOUT_S = 60.0      # a save pickles at most a few MB: far longer than any holder needs
_MARK = "__surgsim_cache_locked__"
_THREAD_LOCK = threading.RLock()


def lock_path() -> str:
    """The lock file: one per user and host, in the temporary folder."""
    uid = os.getuid() if hasattr(os, "getuid") else os.environ.get("USERNAME", "user")
    return os.path.join(tempfile.gettempdir(), f"surgsim-numba-cache-{uid}.lock")


def enabled() -> bool:
    return os.environ.get("SURGSIM_NUMBA_CACHE_LOCK", "1").strip().lower() not in ("0", "false", "no", "off")


@contextlib.contextmanager
def cache_lock(timeout_s: float = TIMEOUT_S):
    """Hold the cache lock (this process's threads and every process of this user on this host)
    for the body; where the file lock cannot be had within ``timeout_s``, run the body anyway.
    Yields whether the file lock is held (False when ``SURGSIM_NUMBA_CACHE_LOCK=0``)."""
    if not enabled():
        yield False
        return
    with _THREAD_LOCK:
        fd = None
        if fcntl is not None:
            try:
                fd = os.open(lock_path(), os.O_RDWR | os.O_CREAT, 0o600)
            except OSError:
                fd = None
        held = False
        if fd is not None:
            deadline = time.monotonic() + timeout_s
            delay = 0.001
            while True:
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    held = True
                    break
                except OSError:
                    if time.monotonic() >= deadline:
                        break
                    time.sleep(delay)
                    delay = min(2 * delay, 0.05)
        try:
            yield held
        finally:
            if fd is not None:
                if held:
                    fcntl.flock(fd, fcntl.LOCK_UN)
                os.close(fd)


def _locked(method):
    @functools.wraps(method)
    def wrapper(*args, **kwargs):
        with cache_lock():
            return method(*args, **kwargs)

    setattr(wrapper, _MARK, True)
    return wrapper


def patch(caching) -> bool:
    """Wrap the index-and-data methods of ``caching.IndexDataCacheFile`` in the lock (once).
    Returns whether they are locked now; False where the class or a method is missing (another
    numba), which leaves numba as it is."""
    cls = getattr(caching, "IndexDataCacheFile", None)
    if cls is None or not all(callable(getattr(cls, name, None)) for name in LOCKED_METHODS):
        return False
    for name in LOCKED_METHODS:
        method = getattr(cls, name)
        if not getattr(method, _MARK, False):
            setattr(cls, name, _locked(method))
    return True


def is_installed() -> bool:
    """Whether numba's caching module is loaded and its cache files are locked."""
    caching = sys.modules.get(CACHING_MODULE)
    cls = getattr(caching, "IndexDataCacheFile", None)
    return cls is not None and all(getattr(getattr(cls, n, None), _MARK, False) for n in LOCKED_METHODS)


def install() -> None:
    """Lock numba's cache files now if numba's caching module is loaded, else when it loads."""
    if enabled():
        after_import(CACHING_MODULE, patch)
