"""Where the time of one :class:`~surgsim_envs.vector.SurgSimVectorEnv` step goes: the timing
instrument behind ``surgsim bench envs --vector-accounting`` (:mod:`surgsim_envs.bench.vector_accounting`).

The vector env's own code is timed from outside: the main process's phases by a subclass that
repeats ``step_async``/``step_wait`` with clock reads in between, the workers' by wrapping, before
the workers fork, the IPC calls and each env's ``step`` in the worker module (so this needs the
``fork`` start method, Linux's default). Clock: ``time.perf_counter`` (CLOCK_MONOTONIC, the same
clock in every process), so a worker's wake-up can be set against the main process's send.

Per vector step (us, medians over steps):

- main: ``actions`` (check and write actions), ``send`` (the step signals), ``wait`` (blocked
  until every worker replied), ``absorb`` (reply payloads), ``copy`` (observations, rewards,
  terminations, truncations), ``infos`` (the info dict);
- per worker: ``wake`` (the main process's last send to the worker's read returning), ``env`` (its envs' ``step``
  calls), ``pack`` (the rest of its step: obs/reward writes, info packing, autoreset bookkeeping),
  ``reply`` (the worker's signal to the main process's wait returning, for the last worker),
  ``idle`` (blocked waiting for a command).
"""

from __future__ import annotations

import multiprocessing as mp
import time

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.vector import ipc
from surgsim_envs.vector import worker as vector_worker

_clock = time.perf_counter
#: per worker per step: wait start, read returned, env time sum, step done, reply sent
_WFIELDS = ("wait_start", "woke", "env", "stepped", "replied")


class _TimedEnv:
    """Forwards everything to ``env``; adds the time spent in ``step`` to ``acc[0]``."""

    def __init__(self, env, acc):
        self._env, self._acc = env, acc

    def step(self, action):
        t0 = _clock()
        out = self._env.step(action)
        self._acc[0] += _clock() - t0
        return out

    def __getattr__(self, name):
        return getattr(self._env, name)


def _instrument_workers(record, n_steps: int, slot_of_lo: dict):
    """Patch the worker module (in this process, inherited by forked workers) to record each
    STEP's timestamps into ``record`` (a shared float64 array ``(workers, n_steps, 5)``).
    Returns a function that undoes the patches."""
    Worker = vector_worker._Worker
    orig_init, orig_step = Worker.__init__, Worker.step
    orig_receive, orig_send_ok, orig_send = ipc.receive, ipc.send_ok, ipc.send
    state = {"w": None, "k": -1, "acc": [0.0], "t_wait": 0.0, "t_woke": 0.0}

    def init(self, *a, **kw):
        orig_init(self, *a, **kw)
        state["w"] = slot_of_lo.get(self.lo)
        self.envs = [_TimedEnv(e, state["acc"]) for e in self.envs]

    def step(self):
        state["acc"][0] = 0.0
        out = orig_step(self)
        k = state["k"] = state["k"] + 1
        w = state["w"]
        if w is not None and 0 <= k < n_steps:
            rec = np.frombuffer(record, dtype=np.float64).reshape(-1, n_steps, len(_WFIELDS))
            rec[w, k, :4] = state["t_wait"], state["t_woke"], state["acc"][0], _clock()
        return out

    def receive(fd):
        state["t_wait"] = _clock()
        out = orig_receive(fd)
        state["t_woke"] = _clock()
        return out

    def stamp_reply():
        k, w = state["k"], state["w"]
        if w is not None and 0 <= k < n_steps:
            np.frombuffer(record, dtype=np.float64).reshape(-1, n_steps, len(_WFIELDS))[w, k, 4] = _clock()

    def send_ok(fd):
        stamp_reply()
        orig_send_ok(fd)

    def send(fd, op, payload=None):
        stamp_reply()
        orig_send(fd, op, payload)

    Worker.__init__, Worker.step = init, step
    ipc.receive, ipc.send_ok, ipc.send = receive, send_ok, send

    def undo():
        Worker.__init__, Worker.step = orig_init, orig_step
        ipc.receive, ipc.send_ok, ipc.send = orig_receive, orig_send_ok, orig_send
    return undo


def _timed_step(vec, actions, t: list) -> None:
    """One ``vec.step(actions)`` (the same calls as ``step_async`` + ``step_wait``) with the
    main-process phase boundaries appended to ``t``."""
    t0 = _clock()
    vec._check_usable()
    acts = vec._v["actions"]
    a = np.asarray(actions)
    acts[...] = a
    t1 = _clock()
    for fd in vec._cmd_fds.values():
        ipc.send_step(fd)
    vec._waiting = False
    t2 = _clock()
    replies = vec._gather(ipc.OK, "step")
    t3 = _clock()
    other, final_other = vec._absorb(replies)
    t4 = _clock()
    v = vec._v
    out = (v["obs"].copy(), v["rewards"].copy(), v["terminations"].copy(), v["truncations"].copy())
    t5 = _clock()
    vec._infos(other, final_other)
    t6 = _clock()
    t.append((t0, t1, t2, t3, t4, t5, t6))
    return out


def account(make_vec, actions, warmup: int = 20) -> dict:
    """Time ``len(actions) - warmup`` steps of the vector env ``make_vec()`` (a
    ``functools.partial`` of :class:`SurgSimVectorEnv` with ``num_envs`` and ``workers``
    keywords, built here after the worker module is patched; not ``in_main``). Returns medians
    in us per vector step; ``worker_*`` are medians over workers and steps."""
    n_steps = len(actions)
    if n_steps <= warmup:
        raise ConfigError(f"the accounting times the steps after {warmup} warm-up steps: it needs more than {warmup} "
                          f"steps (--steps), got {n_steps}")
    ctx = mp.get_context("fork")
    record = ctx.RawArray("d", 64 * n_steps * len(_WFIELDS))
    slot_of_lo: dict = {}
    # worker slots by first env index are only known after the vector env splits its envs: the
    # split is np.linspace(0, n, workers + 1), recomputed here from the arguments
    num_envs, workers = make_vec.keywords["num_envs"], make_vec.keywords["workers"]
    if not 1 <= workers <= 64 or make_vec.keywords.get("in_main"):
        raise ConfigError(f"the accounting times 1..64 worker processes without in_main, got workers={workers!r}, "
                          f"in_main={make_vec.keywords.get('in_main')!r}")
    bounds = np.linspace(0, num_envs, workers + 1).round().astype(int)
    for w in range(workers):
        slot_of_lo[int(bounds[w])] = w
    undo = _instrument_workers(record, n_steps, slot_of_lo)
    try:
        vec = make_vec()
    finally:
        undo()
    main = []
    try:
        vec.reset(seed=0)
        for a in actions:
            _timed_step(vec, a, main)
    finally:
        vec.close()
    rec = np.frombuffer(record, dtype=np.float64).reshape(-1, n_steps, len(_WFIELDS))[:workers, warmup:]
    m = np.asarray(main[warmup:])
    d = np.diff(m, axis=1) * 1e6
    out = {f"main_{k}_us": float(np.median(d[:, i]))
           for i, k in enumerate(("actions", "send", "wait", "absorb", "copy", "infos"))}
    out["main_total_us"] = float(np.median(m[:, -1] - m[:, 0]) * 1e6)
    sent, waited = m[:, 2], m[:, 3]
    wake = (rec[:, :, 1] - sent[None, :]) * 1e6
    env = rec[:, :, 2] * 1e6
    pack = (rec[:, :, 3] - rec[:, :, 1]) * 1e6 - env
    reply = (waited - rec[:, :, 4].max(axis=0)) * 1e6
    idle = (rec[:, :, 1] - rec[:, :, 0]) * 1e6
    out.update(worker_wake_us=float(np.median(wake)), worker_env_us=float(np.median(env)),
               worker_pack_us=float(np.median(pack)), worker_pack_per_env_us=float(np.median(pack)) * workers / num_envs,
               last_reply_us=float(np.median(reply)), worker_idle_us=float(np.median(idle)),
               worker_signal_us=float(np.median((rec[:, :, 4] - rec[:, :, 3]) * 1e6)))
    out["num_envs"], out["workers"] = int(num_envs), int(workers)
    return out
