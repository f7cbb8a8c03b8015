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


def test_caches_go_only_when_a_numba_module_changes(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)      # the caches next to the modules
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


def test_a_broken_stamp_or_missing_folder_never_raises(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__pycache__").mkdir()
    (pkg / "__pycache__" / nc.STAMP_NAME).write_text("garbage")
    assert nc.invalidate_stale_caches(pkg) == 0
    assert nc.invalidate_stale_caches(tmp_path / "missing") == 0


def test_the_package_keeps_a_stamp_after_import():
    import surgsim_envs

    stamp = nc.stamp_path()                # next to the modules, or in NUMBA_CACHE_DIR when it is set
    if os.access(stamp.parent.parent if not os.environ.get("NUMBA_CACHE_DIR") else stamp.parent, os.W_OK):
        files, kernels = stamp.read_text().split()
        assert files == nc.files_stamp() and kernels == nc.kernels_stamp()
    assert surgsim_envs.__version__


def _stamped_package(tmp_path, kernels="k1"):
    pkg = tmp_path / "pkg"
    (pkg / "__pycache__").mkdir(parents=True)
    (pkg / "__pycache__" / nc.STAMP_NAME).write_text(f"files {kernels}")
    _caches(pkg)
    return pkg


def test_a_stage_is_warm_until_its_caches_go_or_the_kernels_change(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    pkg = _stamped_package(tmp_path)
    assert nc.is_warm("demo: grasp scene", pkg) is False              # never warmed
    nc.mark_warm(["demo: grasp scene"], pkg)
    assert nc.is_warm("demo: grasp scene", pkg) is True
    assert nc.is_warm("task: SurgSim/Grasp-v0", pkg) is False          # another stage
    nc.mark_warm(["task: SurgSim/Grasp-v0"], pkg)                      # marks add up
    assert nc.is_warm("demo: grasp scene", pkg) and nc.is_warm("task: SurgSim/Grasp-v0", pkg)
    nc.cache_files(pkg)[0].unlink()                                    # a cache file deleted by hand
    assert nc.is_warm("demo: grasp scene", pkg) is False
    _caches(pkg)
    (pkg / "__pycache__" / nc.STAMP_NAME).write_text("files k2")      # the kernel sources changed
    assert nc.is_warm("demo: grasp scene", pkg) is False
    nc.mark_warm(["demo: grasp scene"], pkg)                           # a new mark forgets the old sources' stages
    assert nc.is_warm("demo: grasp scene", pkg) and not nc.is_warm("task: SurgSim/Grasp-v0", pkg)


def test_warm_state_is_unknown_where_numba_caches_elsewhere(tmp_path, monkeypatch):
    pkg = _stamped_package(tmp_path)
    nc.mark_warm(["demo: grasp scene"], pkg)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "elsewhere"))
    assert nc.is_warm("demo: grasp scene", pkg) is None


def test_run_stages_counts_the_kernels_really_compiled():
    import numba

    from surgsim_envs.scene.kernel_warmup import Stage, run_stages

    @numba.njit(cache=False)
    def triple(x):
        return 3 * x

    stages = [Stage("first call", lambda: triple(2.0)), Stage("again", lambda: triple(5.0)),
              Stage("new type", lambda: triple(2))]
    res = run_stages(stages, progress=False, mark=False)
    assert [r.kernels_compiled for r in res] == [1, 0, 1]
    assert res[0].kernels == [f"{__name__}.test_run_stages_counts_the_kernels_really_compiled.<locals>.triple"]


def test_caches_under_numba_cache_dir_go_when_a_numba_module_changes(tmp_path, monkeypatch):
    """With NUMBA_CACHE_DIR set numba caches each source folder in a folder of its own there; the
    same check clears those (and only those) when a numba module changes."""
    import subprocess
    import sys

    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    _write(pkg / "sub" / "k.py", "from numba import njit\n\n\n@njit(cache=True)\ndef kern(x):\n    return x + 1\n")
    cache_root = tmp_path / "numba_cache_dir"
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(cache_root))
    # numba itself writes the kernel's cache where external_cache_dirs says it does
    env = {**os.environ, "PYTHONPATH": str(pkg / "sub")}
    subprocess.run([sys.executable, "-c", "import k; assert k.kern(1) == 2"], check=True, env=env, cwd=tmp_path)
    written = nc.external_cache_files(pkg)
    assert written and all(f.parent in nc.external_cache_dirs(pkg) for f in written)
    other = cache_root / "elsewhere_0123"                    # another project's caches: never touched
    other.mkdir()
    (other / "x.kern-1.py311.nbi").write_bytes(b"x")
    assert nc.invalidate_stale_caches(pkg) == len(written)  # no stamp yet: unknown caches go
    subprocess.run([sys.executable, "-c", "import k; assert k.kern(1) == 2"], check=True, env=env, cwd=tmp_path)
    n = len(nc.external_cache_files(pkg))
    assert n and nc.invalidate_stale_caches(pkg) == 0      # nothing changed: kept
    assert not (pkg / "__pycache__" / nc.STAMP_NAME).exists()   # the stamp lives in NUMBA_CACHE_DIR
    assert nc.stamp_path(pkg).parent == cache_root and nc.stamp_path(pkg).is_file()
    _write(pkg / "sub" / "k.py", "from numba import njit\n\n\n@njit(cache=True)\ndef kern(x):\n    return x + 2\n")
    assert nc.invalidate_stale_caches(pkg) == n and nc.external_cache_files(pkg) == []
    assert (other / "x.kern-1.py311.nbi").is_file()
