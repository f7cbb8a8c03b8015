"""Keep numba's on-disk caches true to the sources.

The kernels are compiled with ``@njit(cache=True)``; numba stores the machine code in
``__pycache__/*.nbi`` / ``*.nbc`` next to each module and checks only the *function's own file*
when it loads it. A kernel that calls (or inlines) a kernel from another file keeps the old callee
after that other file changes (a ``git pull``, an upgrade, an edit): the physics would silently be
the previous version's. On import of the package, :func:`invalidate_stale_caches` compares a
stamp of the sources of the package's numba modules with the one stored beside the caches and, if
they differ, deletes the package's numba cache files, so that every kernel is compiled again from
the current sources.

Cold or warm: :func:`mark_warm` (called by ``surgsim warmup`` and by the demo after it compiled)
records, beside the stamp, which warm-up stages built the caches, for which kernel sources and
how many cache files there were; :func:`is_warm` says whether a stage's caches are still there
(False after a source change, ``--clear`` or deleted cache files), so the demo can compile ahead
with a progress bar instead of stalling on its first step.

With ``NUMBA_CACHE_DIR`` set (common where the installed package is read-only, e.g. a cluster's
site-packages), numba keeps each source folder's caches in ``NUMBA_CACHE_DIR/<folder
name>_<SHA-1 of the folder's absolute path>`` (numba's ``get_suitable_cache_subpath``, numba
0.5x-0.6x); the same check then runs on those folders, with its stamp in ``NUMBA_CACHE_DIR`` itself
(:func:`external_cache_dirs`), so a stale callee cannot survive there either. The user-wide cache
numba falls back to when the package folder is read-only and ``NUMBA_CACHE_DIR`` is unset is left
alone. ``python -m surgsim_envs.numba_cache --clear`` deletes the package's caches by hand.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

from surgsim_envs.numba_cache_lock import cache_lock

PACKAGE = Path(__file__).resolve().parent
STAMP_NAME = "numba_sources.stamp"
WARM_NAME = "numba_warm.json"
CACHE_SUFFIXES = (".nbi", ".nbc")


def _py_files(package: Path) -> list[str]:
    """Every .py file under ``package`` (not descending into __pycache__), sorted."""
    out = []
    for root, dirs, files in os.walk(package):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        out.extend(os.path.join(root, f) for f in sorted(files) if f.endswith(".py"))
    return out


def files_stamp(package: Path = PACKAGE) -> str:
    """A cheap digest of (path, size, mtime in ns) of every .py file under ``package``."""
    parts = []
    for path in _py_files(package):
        st = os.stat(path)
        parts.append(f"{path}\0{st.st_size}\0{st.st_mtime_ns}")
    return hashlib.sha1("\n".join(parts).encode()).hexdigest()


def kernels_stamp(package: Path = PACKAGE) -> str:
    """A digest of the path and content of every .py file under ``package`` that uses numba."""
    h = hashlib.sha1()
    for path in _py_files(package):
        with open(path, "rb") as fh:
            text = fh.read()
        if b"numba" in text:
            h.update(os.path.relpath(path, package).encode() + b"\0" + hashlib.sha1(text).digest())
    return h.hexdigest()


def cache_files(package: Path = PACKAGE) -> list[Path]:
    """The numba cache files numba wrote next to the package's modules."""
    out = []
    for root, dirs, files in os.walk(package):
        if os.path.basename(root) == "__pycache__":
            out.extend(Path(root) / f for f in files if f.endswith(CACHE_SUFFIXES))
    return out


def external_cache_dirs(package: Path = PACKAGE) -> list[Path]:
    """The folders numba keeps the package's caches in when ``NUMBA_CACHE_DIR`` is set (module
    docstring): one per source folder, named as numba names it; [] when it is unset."""
    root = os.environ.get("NUMBA_CACHE_DIR")
    if not root:
        return []
    folders = set()
    for path in _py_files(package):
        for form in (os.path.abspath(path), os.path.realpath(path)):
            folders.add(os.path.dirname(form))
    return [Path(root) / f"{os.path.basename(d)}_{hashlib.sha1(d.encode()).hexdigest()}" for d in sorted(folders)]


def external_cache_files(package: Path = PACKAGE) -> list[Path]:
    """The numba cache files of the package under ``NUMBA_CACHE_DIR`` (:func:`external_cache_dirs`)."""
    out = []
    for folder in external_cache_dirs(package):
        if folder.is_dir():
            out.extend(sorted(f for f in folder.iterdir() if f.name.endswith(CACHE_SUFFIXES)))
    return out


def _delete(paths) -> int:
    n = 0
    for path in paths:
        try:
            path.unlink()
            n += 1
        except OSError:
            pass
    return n


def clear_caches(package: Path = PACKAGE) -> int:
    """Delete the package's numba cache files, next to its modules and under ``NUMBA_CACHE_DIR``;
    returns how many were deleted (files another process deletes at the same time are skipped)."""
    return _delete(cache_files(package) + external_cache_files(package))


def invalidate_stale_caches(package: Path = PACKAGE) -> int:
    """If a numba module's source changed since the stamp was written, delete the package's numba
    caches and write the new stamp. Returns the number of cache files deleted (0 when nothing
    changed or the package folder is not writable). Two levels: a stat of every .py file (about a
    millisecond); only when that changed, the content of the numba modules (so an edit elsewhere,
    or a checkout that only touches mtimes, keeps the caches). With ``NUMBA_CACHE_DIR`` set the
    caches and the stamp live there (:func:`invalidate_external_caches`). Runs under the cache
    lock (:mod:`surgsim_envs.numba_cache_lock`), so processes importing the package together
    neither delete what another just compiled nor race on the stamp. Never raises: a failure only
    costs a recompilation."""
    with cache_lock():
        return _invalidate_stale_caches(package)


def _invalidate_stale_caches(package: Path) -> int:
    if os.environ.get("NUMBA_CACHE_DIR"):
        return invalidate_external_caches(package)
    try:
        stamp_dir = package / "__pycache__"
        stamp = stamp_dir / STAMP_NAME
        files = files_stamp(package)
        try:
            old_files, old_kernels = stamp.read_text().split()
        except (OSError, ValueError):
            old_files = old_kernels = ""
        if files == old_files:
            return 0
        if not os.access(package, os.W_OK):
            return 0
        kernels = kernels_stamp(package)
        deleted = clear_caches(package) if kernels != old_kernels else 0
        stamp_dir.mkdir(exist_ok=True)
        tmp = stamp_dir / f"{STAMP_NAME}.{os.getpid()}"
        tmp.write_text(f"{files} {kernels}")
        os.replace(tmp, stamp)
        return deleted
    except Exception:  # noqa: BLE001 - never stop an import over a cache
        return 0


def stamp_path(package: Path = PACKAGE) -> Path:
    """Where the stamp of the package's caches is kept: ``__pycache__`` next to the package's
    modules, or with ``NUMBA_CACHE_DIR`` set ``NUMBA_CACHE_DIR/<package name>_<SHA-1 of its
    path>.numba_sources.stamp`` (one per package location)."""
    root = os.environ.get("NUMBA_CACHE_DIR")
    if not root:
        return Path(package) / "__pycache__" / STAMP_NAME
    where = os.path.abspath(package)
    return Path(root) / f"{os.path.basename(where)}_{hashlib.sha1(where.encode()).hexdigest()}.{STAMP_NAME}"


def invalidate_external_caches(package: Path = PACKAGE) -> int:
    """:func:`invalidate_stale_caches` for the caches under ``NUMBA_CACHE_DIR``, with the stamp
    there (:func:`stamp_path`). Returns the number of cache files deleted; never raises."""
    try:
        stamp = stamp_path(package)
        root = stamp.parent
        files = files_stamp(package)
        try:
            old_files, old_kernels = stamp.read_text().split()
        except (OSError, ValueError):
            old_files = old_kernels = ""
        if files == old_files:
            return 0
        kernels = kernels_stamp(package)
        deleted = _delete(external_cache_files(package)) if kernels != old_kernels else 0
        root.mkdir(parents=True, exist_ok=True)
        tmp = stamp.with_name(f"{stamp.name}.{os.getpid()}")
        tmp.write_text(f"{files} {kernels}")
        os.replace(tmp, stamp)
        return deleted
    except Exception:  # noqa: BLE001 - never stop an import over a cache
        return 0


def _kernels_in_stamp(package: Path) -> str | None:
    try:
        return (package / "__pycache__" / STAMP_NAME).read_text().split()[1]
    except (OSError, IndexError):
        return None


def caches_here(package: Path = PACKAGE) -> bool:
    """Whether numba writes this package's caches next to its modules (the folder is writable
    and ``NUMBA_CACHE_DIR`` is unset), i.e. whether :func:`is_warm` can tell."""
    return not os.environ.get("NUMBA_CACHE_DIR") and os.access(package, os.W_OK)


def mark_warm(stages, package: Path = PACKAGE) -> None:
    """Record that the warm-up ``stages`` (names) compiled their kernels into the caches. Never
    raises (a missing mark only costs another warm-up)."""
    try:
        if not caches_here(package):
            return
        kernels = _kernels_in_stamp(package) or kernels_stamp(package)
        path = package / "__pycache__" / WARM_NAME
        try:
            old = json.loads(path.read_text())
        except (OSError, ValueError):
            old = {}
        done = set(old.get("stages", [])) if old.get("kernels") == kernels else set()
        record = {"kernels": kernels, "stages": sorted(done | set(stages)), "cache_files": len(cache_files(package))}
        path.parent.mkdir(exist_ok=True)
        tmp = path.with_name(f"{WARM_NAME}.{os.getpid()}")
        tmp.write_text(json.dumps(record))
        os.replace(tmp, path)
    except Exception:  # noqa: BLE001 - never fail a run over a cache mark
        pass


def is_warm(stage: str, package: Path = PACKAGE) -> bool | None:
    """True if ``stage``'s kernels were compiled into the caches since the numba sources last
    changed and no cache file went since; False if not (a fresh checkout, ``--clear``, an edit);
    None where the caches live elsewhere (see :func:`caches_here`) and this cannot tell."""
    if not caches_here(package):
        return None
    try:
        record = json.loads((package / "__pycache__" / WARM_NAME).read_text())
    except (OSError, ValueError):
        return False
    current = _kernels_in_stamp(package) or kernels_stamp(package)
    return (record.get("kernels") == current and stage in record.get("stages", [])
            and len(cache_files(package)) >= int(record.get("cache_files", 0)) > 0)


if __name__ == "__main__":  # pragma: no cover - manual tool
    import sys

    if "--clear" in sys.argv[1:]:
        print(f"deleted {clear_caches()} numba cache files under {PACKAGE}")
    else:
        print(f"deleted {invalidate_stale_caches()} stale numba cache files under {PACKAGE}")
