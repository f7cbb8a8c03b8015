"""numba_cache: the package's numba caches are dropped when a numba module changes (numba itself
checks only each kernel's own file), and kept otherwise."""

import os
import time

from surgsim_envs import numba_cache as nc


def _caches(pkg):
    cache = pkg / "sub" / "__pycache__"
    cache.mkdir(parents=True, exist_ok=True)
    for name in ("k.kern-10.py311.nbi", "k.kern-10.py311.1.nbc"):
        (cache / name).write_bytes(b"x")
    (cache / "k.cpython-311.pyc").write_bytes(b"x")     # not numba's: never touched


def _write(path, text):
    path.write_text(text)
    st = os.stat(path)
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 10_000_000))   # a visible mtime change


def test_caches_go_only_when_a_numba_module_changes(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    _write(pkg / "sub" / "k.py", "from numba import njit\n")
    _write(pkg / "plain.py", "x = 1\n")
    _caches(pkg)
    assert nc.invalidate_stale_caches(pkg) == 2            # no stamp yet: unknown caches go
    _caches(pkg)
    assert nc.invalidate_stale_caches(pkg) == 0            # nothing changed
    assert len(nc.cache_files(pkg)) == 2
    _write(pkg / "plain.py", "x = 2\n")                     # a module without numba changed
    assert nc.invalidate_stale_caches(pkg) == 0 and len(nc.cache_files(pkg)) == 2
    os.utime(pkg / "sub" / "k.py", ns=(time.time_ns(), time.time_ns()))   # touched, same content
    assert nc.invalidate_stale_caches(pkg) == 0 and len(nc.cache_files(pkg)) == 2
    _write(pkg / "sub" / "k.py", "from numba import njit\ny = 3\n")       # a kernel changed
    assert nc.invalidate_stale_caches(pkg) == 2
    assert nc.cache_files(pkg) == [] and (pkg / "sub" / "__pycache__" / "k.cpython-311.pyc").is_file()


def test_a_broken_stamp_or_missing_folder_never_raises(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__pycache__").mkdir()
    (pkg / "__pycache__" / nc.STAMP_NAME).write_text("garbage")
    assert nc.invalidate_stale_caches(pkg) == 0
    assert nc.invalidate_stale_caches(tmp_path / "missing") == 0


def test_the_package_keeps_a_stamp_after_import():
    import surgsim_envs

    stamp = nc.PACKAGE / "__pycache__" / nc.STAMP_NAME
    if os.access(nc.PACKAGE, os.W_OK):
        files, kernels = stamp.read_text().split()
        assert files == nc.files_stamp() and kernels == nc.kernels_stamp()
    assert surgsim_envs.__version__
