"""Compile the numba kernels ahead, with a progress bar that names what compiles.

The physics kernels are ``@njit(cache=True)``: the first process on a checkout compiles them
(tens of seconds on two cores) and later ones load the machine code from ``__pycache__``. A
*stage* is a named callable that exercises some kernels (build a scene, run a few steps);
:func:`run_stages` runs stages under a bar with one tick per stage, whose postfix names the kernel
numba is compiling right now (numba's ``numba:compile`` event fires only on a cache miss, so the
count is the number of kernels really compiled) and whose clock keeps moving during a long
compilation. Afterwards :func:`surgsim_envs.numba_cache.mark_warm` records the stage names, so
the next run knows its caches are warm.
"""

from __future__ import annotations

import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Callable


@dataclass
class Stage:
    """One unit of warm-up: ``name`` (what the bar shows, also the warm-mark key) and ``run()``."""

    name: str
    run: Callable[[], object]


@dataclass
class StageResult:
    name: str
    seconds: float
    kernels_compiled: int
    kernels: list[str] = field(default_factory=list)


from numba.core.event import Listener  # noqa: E402  (numba is imported by every physics module anyway)


class CompileCounter(Listener):
    """Counts numba compilations (cache misses) while installed; ``current`` names the kernel
    being compiled (``module.function``), ``names`` every one in order."""

    def __init__(self):
        self.names: list[str] = []
        self.current = ""
        self._depth = 0

    def on_start(self, event) -> None:
        disp = event.data.get("dispatcher") if isinstance(event.data, dict) else None
        func = getattr(disp, "py_func", None)
        name = f"{getattr(func, '__module__', '?')}.{getattr(func, '__qualname__', '?')}"
        self.names.append(name)
        self.current = name.removeprefix("surgsim_envs.")
        self._depth += 1

    def on_end(self, event) -> None:
        self._depth = max(0, self._depth - 1)
        if not self._depth:
            self.current = ""

    def __enter__(self):
        from numba.core import event

        event.register("numba:compile", self)
        return self

    def __exit__(self, *exc):
        from numba.core import event

        event.unregister("numba:compile", self)


def run_stages(stages: list[Stage], *, desc: str = "compiling kernels", progress: bool = True,
               file=None, refresh_s: float = 0.5, mark: bool = True) -> list[StageResult]:
    """Run ``stages`` in order under a progress bar (stderr by default); returns per-stage wall
    seconds and the kernels each compiled. Marks every stage warm when all have run (``mark``)."""
    from tqdm import tqdm

    from surgsim_envs.numba_cache import mark_warm

    results: list[StageResult] = []
    stop = threading.Event()
    with CompileCounter() as counter, tqdm(total=len(stages), desc=desc, unit="stage", file=file or sys.stderr,
                                           disable=not progress, mininterval=refresh_s,
                                           bar_format="{desc}: {n}/{total} stages |{bar:20}| [{elapsed}] {postfix}") as bar:
        stage_name = [""]

        def show():
            now = counter.current
            bar.set_postfix_str(f"{stage_name[0]}: {len(counter.names)} kernels compiled"
                                + (f", now {now}" if now else ""), refresh=False)
            bar.refresh()

        def tick():     # keeps the clock and the kernel name moving during a long compilation
            while not stop.wait(refresh_s):
                show()

        ticker = threading.Thread(target=tick, name="kernel-warmup-progress", daemon=True)
        if progress:
            ticker.start()
        try:
            for stage in stages:
                stage_name[0] = stage.name
                before = len(counter.names)
                t0 = time.perf_counter()
                stage.run()
                results.append(StageResult(stage.name, time.perf_counter() - t0, len(counter.names) - before,
                                           counter.names[before:]))
                bar.update(1)
            stage_name[0] = "done"
            if progress:
                show()
        finally:
            stop.set()
            if ticker.is_alive():
                ticker.join()
    if mark:
        mark_warm([s.name for s in stages])
    return results
