"""numba_cache_lock: processes that compile specialisations of one cached kernel at the same time
share one numba cache safely (numba's own save picks the same data-file number in each of them)."""

import os
import subprocess
import sys
import textwrap
import time

import pytest

KERNEL = textwrap.dedent("""
    from numba import njit

    @njit(cache=True)
    def twice_plus_one(x):
        return x * 2 + 1
""")

# one specialisation each; every process compiles all of them, in its own order
VALUES = textwrap.dedent("""
    import numpy as np
    VALUES = [np.int64(3), np.float64(1.5), np.float32(2.25), np.complex128(1 + 2j), np.int32(7),
              np.uint8(9), np.arange(3.0), np.ones((2, 2)), np.arange(4), np.int16(5),
              np.arange(3, dtype=np.float32), np.arange(6.0).reshape(2, 3)[:, ::2]]
""")

COMPILER = textwrap.dedent("""
    import sys, time
    import surgsim_envs                  # locks numba's cache files when numba loads
    import numpy as np
    from values import VALUES
    from kern import twice_plus_one
    start, seed = float(sys.argv[1]), int(sys.argv[2])
    order = np.random.default_rng(seed).permutation(len(VALUES))
    while time.time() < start:
        time.sleep(0.001)
    for i in order:
        twice_plus_one(VALUES[i])
""")

CHECKER = textwrap.dedent("""
    import numpy as np
    import surgsim_envs
    from values import VALUES
    from kern import twice_plus_one
    bad = []
    for v in VALUES:
        got, want = twice_plus_one(v), v * 2 + 1
        if not np.array_equal(got, want):     # numba's own promotions (float32 * 2 is float64)
            bad.append((repr(v), repr(got)))
    print("misses", sum(twice_plus_one.stats.cache_misses.values()), "bad", bad)
""")


def _run_race(tmp_path, processes: int, lock: bool):
    for name, text in (("kern.py", KERNEL), ("values.py", VALUES), ("compile.py", COMPILER), ("check.py", CHECKER)):
        (tmp_path / name).write_text(text)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(tmp_path),
               SURGSIM_NUMBA_CACHE_LOCK="1" if lock else "0")
    start = time.time() + 4.0              # all processes imported numba by then, then compile together
    procs = [subprocess.Popen([sys.executable, "compile.py", str(start), str(seed)], cwd=tmp_path, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for seed in range(processes)]
    for p in procs:
        _, err = p.communicate(timeout=300)
        assert p.returncode == 0, err[-2000:]
    return subprocess.run([sys.executable, "check.py"], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=300)


@pytest.mark.slow
def test_processes_compiling_together_leave_a_cache_every_process_can_load(tmp_path):
    """End to end: three processes compile twelve specialisations of one kernel at once (the race is
    a few milliseconds wide, so this rarely fails even without the lock; the next test shows the
    lock is taken)."""
    out = _run_race(tmp_path, processes=3, lock=True)
    assert out.returncode == 0, out.stderr[-2000:]
    # every specialisation loads from the cache (no compile) and computes with its own types
    assert out.stdout.split() == ["misses", "0", "bad", "[]"], out.stdout + out.stderr[-2000:]
    index = list((tmp_path / "cache").rglob("kern.twice_plus_one-*.nbi"))
    data = list((tmp_path / "cache").rglob("kern.twice_plus_one-*.nbc"))
    assert len(index) == 1 and len(data) == 12


HOLDER = textwrap.dedent("""
    import os, time
    from surgsim_envs.numba_cache_lock import cache_lock
    while not os.path.exists("ready"):          # the writer has imported the package and numba
        time.sleep(0.01)
    with cache_lock() as held:
        print("held" if held else "not held", flush=True)
        open("go", "w").close()
        time.sleep(1.5)
        released = time.time()
    print(released, flush=True)
""")

WRITER = textwrap.dedent("""
    import os, time
    import surgsim_envs
    import numba.core.caching
    from kern import twice_plus_one
    open("ready", "w").close()
    while not os.path.exists("go"):
        time.sleep(0.01)
    twice_plus_one(2.0)                 # compiles (not under the lock), then loads and saves the cache
    print(time.time())
""")


def test_numba_saves_its_cache_only_while_no_other_process_holds_the_lock(tmp_path):
    """A process holding the lock keeps every other process's cache save waiting: numba's
    read-index, pick-a-number, write-index, write-data sequence cannot interleave."""
    for name, text in (("kern.py", KERNEL), ("hold.py", HOLDER), ("write.py", WRITER)):
        (tmp_path / name).write_text(text)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(tmp_path),
               TMPDIR=str(tmp_path), SURGSIM_NUMBA_CACHE_LOCK="1")        # a lock file of this test's own
    writer = subprocess.Popen([sys.executable, "write.py"], cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    holder = subprocess.Popen([sys.executable, "hold.py"], cwd=tmp_path, env=env, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        released = float(holder.stdout.readline())
        out, err = writer.communicate(timeout=120)
    finally:
        for p in (holder, writer):
            p.kill()
            p.wait()
    assert writer.returncode == 0, err[-2000:]
    assert float(out.split()[-1]) >= released
    assert len(list((tmp_path / "cache").rglob("kern.twice_plus_one-*.nbc"))) == 1


def test_the_lock_is_installed_when_numba_loads_and_not_before():
    code = ("import sys, surgsim_envs; from surgsim_envs.numba_cache_lock import is_installed; "
            "print('numba' in sys.modules, is_installed()); import numba.core.caching; print(is_installed())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env=dict(os.environ, SURGSIM_NUMBA_CACHE_LOCK="1"))
    assert out.stdout.split() == ["False", "False", "True"], out.stdout + out.stderr


def test_a_held_lock_delays_then_gives_way_instead_of_hanging(tmp_path, monkeypatch):
    from surgsim_envs import numba_cache_lock as ncl

    monkeypatch.setattr(ncl, "lock_path", lambda: str(tmp_path / "lock"))
    holder = subprocess.Popen([sys.executable, "-c", (
        "import fcntl, os, sys, time; fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT); "
        "fcntl.flock(fd, fcntl.LOCK_EX); print('held', flush=True); time.sleep(30)"), str(tmp_path / "lock")],
        stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        t0 = time.monotonic()
        with ncl.cache_lock(timeout_s=0.5) as held:
            waited = time.monotonic() - t0
        assert held is False and 0.5 <= waited < 5.0
    finally:
        holder.kill()
        holder.wait()
    with ncl.cache_lock(timeout_s=0.5) as held:        # released with its holder's death
        assert held is True
