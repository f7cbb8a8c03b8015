"""Where numba's first-use compile goes: a pytest plugin that times every ``Dispatcher.compile``.

Run the suite from empty caches (a fresh clone, or an empty ``NUMBA_CACHE_DIR``) with it loaded,
then summarise::

    NUMBA_CACHE_DIR=$(mktemp -d) PYTHONPATH=scripts pytest -n 0 -p numba_compile_profile
    python scripts/numba_compile_profile.py numba_compile_profile.json

Each compile is recorded with its function, signature, wall seconds, nesting depth (a kernel
compiles the kernels it calls inside its own compile) and the test that triggered it; the summary
gives the total of the top-level compiles and each function's exclusive seconds (its own, without
the callees it compiled) with its number of specialisations. Two specialisations of one function
usually mean a caller passed a literal constant or another array layout. ``NUMBA_PROFILE_OUT``
sets the JSON file (default ``numba_compile_profile.json`` in the working folder).
"""
from __future__ import annotations

import collections
import json
import os
import sys
import threading
import time

RECORDS: list[dict] = []
_DEPTH = threading.local()
_TEST = ["<collection>"]


def _install() -> None:
    import numba.core.dispatcher as nd

    original = nd.Dispatcher.compile

    def timed_compile(self, sig):
        depth = getattr(_DEPTH, "value", 0)
        _DEPTH.value = depth + 1
        before = len(self.overloads)
        start = time.perf_counter()
        try:
            return original(self, sig)
        finally:
            seconds = time.perf_counter() - start
            _DEPTH.value = depth
            if len(self.overloads) > before:
                RECORDS.append({"fn": f"{self.py_func.__module__}.{self.py_func.__qualname__}", "sig": str(sig),
                                "secs": seconds, "depth": depth, "test": _TEST[0]})

    nd.Dispatcher.compile = timed_compile


def pytest_configure(config):
    _install()


def pytest_runtest_setup(item):
    _TEST[0] = item.nodeid


def pytest_sessionfinish(session, exitstatus):
    with open(os.environ.get("NUMBA_PROFILE_OUT", "numba_compile_profile.json"), "w") as fh:
        json.dump(RECORDS, fh)


def summarise(records: list[dict], top: int = 30) -> str:
    """Total top-level compile seconds and the functions with the most exclusive seconds."""
    exclusive = []
    for i, rec in enumerate(records):              # callees finish (and are recorded) before their caller
        children, j = 0.0, i - 1
        while j >= 0 and records[j]["depth"] > rec["depth"]:
            if records[j]["depth"] == rec["depth"] + 1:
                children += records[j]["secs"]
            j -= 1
        exclusive.append(rec["secs"] - children)
    per_fn = collections.defaultdict(lambda: [0.0, 0])
    for rec, secs in zip(records, exclusive):
        per_fn[rec["fn"]][0] += secs
        per_fn[rec["fn"]][1] += 1
    total = sum(r["secs"] for r in records if r["depth"] == 0)
    lines = [f"{total:.1f} s in {sum(r['depth'] == 0 for r in records)} top-level compiles "
             f"({len(records)} with the nested ones)", "exclusive s  specialisations  function"]
    for fn, (secs, n) in sorted(per_fn.items(), key=lambda kv: -kv[1][0])[:top]:
        lines.append(f"{secs:11.1f}  {n:15d}  {fn}")
    return "\n".join(lines)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python scripts/numba_compile_profile.py PROFILE.json")
    with open(sys.argv[1]) as fh:
        print(summarise(json.load(fh)))
