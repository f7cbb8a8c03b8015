"""CUDA graphs of a batch's physics steps: each kind of physics call is captured once and replayed.

One physics step of a batch is about a hundred kernel launches (ten of ours, the rest MuJoCo Warp's
``step1`` / ``step2``), and packing one launch's arguments costs tens of microseconds of Python:
an env step of ten physics steps pays ~60 ms of launches whatever the world count (docs/batch.md).
On a CUDA device the whole call (``K`` MuJoCo steps, or ``K`` steps of a control schedule) is
recorded once as a graph (``wp.ScopedCapture``) and replayed with one ``wp.capture_launch``: the
same kernels on the same arrays in the same order, so the same results.

What a captured body may do, and what :class:`BatchSimulation` keeps to: only device work (kernel
launches, device copies, allocations from the device's memory pool); no host read of a device
array and no synchronisation (``tests/test_batch_step_graph.py`` checks every batched task's step
for that on the CPU); arrays that stay where they are (the state, fields and buffers are allocated
once; a schedule's values are copied into a buffer that belongs to the graph). Scalars passed to
kernels are recorded with the graph: the time step and contact constants, which do not change.

Modes: ``"auto"`` (capture on a CUDA device whose memory pool is enabled, Warp's default; plain
launches elsewhere), ``"on"`` (a ConfigError where capture is impossible, e.g. Warp's CPU device)
and ``"off"``. A capture that fails (a driver without graph support) warns once, naming the cause,
and the batch goes on with plain launches.
"""

from __future__ import annotations

import warnings
from typing import Callable, Hashable

from surgsim_envs.errors import ConfigError

GRAPH_MODES = ("auto", "on", "off")


def capture_with_warp(wp, device) -> Callable[[Callable[[], None]], object]:
    """The capture of one body on ``device``: ``wp.ScopedCapture`` (records, runs nothing) -> the graph."""

    def capture(body: Callable[[], None]):
        with wp.ScopedDevice(device), wp.ScopedCapture(device=device) as cap:
            body()
        return cap.graph

    return capture


class StepGraphs:
    """Captured graphs of a batch's physics calls, keyed by what the call does (module docstring).

    ``run(key, body)`` replays the graph recorded for ``key`` (recording ``body`` the first time);
    where graphs are off it calls ``body``. ``capture`` and ``launch`` are Warp's
    (``capture_with_warp`` and ``wp.capture_launch``) unless given.
    """

    def __init__(self, wp, device, mode: str = "auto", *, capture=None, launch=None):
        if mode not in GRAPH_MODES:
            raise ConfigError(f"graphs={mode!r}: use 'auto' (CUDA graphs on a GPU, plain launches elsewhere), "
                              "'on' or 'off'")
        dev = wp.get_device(device)
        possible = bool(dev.is_cuda) and bool(wp.is_mempool_enabled(dev))
        if mode == "on" and not possible:
            why = ("Warp's CPU device cannot capture graphs" if not dev.is_cuda else
                   f"the memory pool of {dev} is disabled (wp.set_mempool_enabled('{dev}', True) enables it; "
                   "MuJoCo Warp allocates its temporaries inside a step)")
            raise ConfigError(f"graphs='on' on device {dev}: {why}; use graphs='auto' or 'off'")
        self.device = dev
        self.mode = mode
        #: True while calls are captured and replayed
        self.enabled = possible and mode != "off"
        #: why capture was given up ("" while it works or was never tried)
        self.failure = ""
        self._capture = capture or capture_with_warp(wp, dev)
        self._launch = launch or wp.capture_launch
        self._wp = wp
        self._graphs: dict[Hashable, object] = {}
        self.captures = 0
        self.replays = 0

    def run(self, key: Hashable, body: Callable[[], None]) -> None:
        """Replay the graph of ``key`` (recording ``body`` into it first if new); ``body`` itself
        where graphs are off or capture has failed."""
        if not self.enabled:
            body()
            return
        graph = self._graphs.get(key)
        if graph is None:
            try:
                graph = self._capture(body)
            except Exception as exc:          # e.g. no graph support in the driver: plain launches from now on
                self.enabled = False
                self.failure = f"{type(exc).__name__}: {exc}"
                warnings.warn(f"CUDA graph capture of the batched physics failed on {self.device} ({self.failure}); "
                              "the batch continues with plain kernel launches (graphs='off' silences this)",
                              RuntimeWarning, stacklevel=3)
                self._graphs.clear()
                body()
                return
            self._graphs[key] = graph
            self.captures += 1
        with self._wp.ScopedDevice(self.device):
            self._launch(graph)
        self.replays += 1

    def clear(self) -> None:
        """Forget every graph (after an array a graph uses was replaced)."""
        self._graphs.clear()

    def __len__(self) -> int:
        return len(self._graphs)
