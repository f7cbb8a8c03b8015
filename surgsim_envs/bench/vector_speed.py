"""Vector env figures for ``surgsim bench envs --vector`` (the async aim: 2 workers
>= 1.7x one process): one env in this process, Gymnasium's AsyncVectorEnv and
:class:`~surgsim_envs.vector.SurgSimVectorEnv` (``gym.make_vec``'s default for our tasks),
all built up front and timed **alternately** in rounds (same load for each), for the task and for
a busy-wait stand-in env of a given step time that returns the task's info dict (the ceiling any
vector env can reach at that step time). Also the signal round trip of the IPC options the
vector env could use (``--signal-options``)."""

from __future__ import annotations

import functools
import os
import statistics
import time

import numpy as np

from surgsim_envs.bench.random_actions import random_actions
from surgsim_envs.bench.spin_env import SpinEnv
from surgsim_envs.errors import ConfigError

#: s, a vector step that takes longer raises instead of hanging
STEP_TIMEOUT = 60.0


def _run_single(env, acts):
    t0 = time.perf_counter()
    for a in acts:
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    return len(acts) / (time.perf_counter() - t0)


def _run_vector(vec, acts):
    """Env steps/s (vector steps x num_envs); the vector env autoresets by itself."""
    if _runs_itself(vec):
        return vec.run(len(acts))
    t0 = time.perf_counter()
    for a in acts:
        vec.step(a)
    return len(acts) * vec.num_envs / (time.perf_counter() - t0)


def _independent_child(env_id, seed: int, conn, palpation: bool) -> None:
    """One env in its own process: steps ``n`` random actions per request, resets when an episode ends."""
    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401  (registers the tasks)

    env = gym.make(env_id) if isinstance(env_id, str) else env_id()
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    conn.send(os.getpid())
    while True:
        n = conn.recv()
        if n is None:
            break
        for a in random_actions(env.action_space, n, rng, palpation):
            _, _, te, tr, _ = env.step(a)
            if te or tr:
                env.reset()
        conn.send(n)
    env.close()


class IndependentProcesses:
    """The ceiling of any vector env on this machine: ``workers`` processes, one env each, that
    step the same number of random actions each, with no exchange between steps (one message at the
    start and one at the end of a run). Timed by :func:`alternate` like a vector env
    (``num_envs`` = ``workers``); its rate over one env's in the same round is what the cores give
    (``independent_speedup`` in ``surgsim bench envs --vector``)."""

    def __init__(self, env_id, workers: int, palpation: bool = False):
        import multiprocessing as mp

        ctx = mp.get_context("fork")
        self.num_envs = int(workers)
        self._conns, self._procs = [], []
        for w in range(self.num_envs):
            a, b = ctx.Pipe()
            p = ctx.Process(target=_independent_child, args=(env_id, 1000 + w, b, palpation), daemon=True)
            p.start()
            self._conns.append(a)
            self._procs.append(p)
        self.worker_pids = [c.recv() for c in self._conns]

    def reset(self, seed=None):
        return None

    def run(self, steps_each: int) -> float:
        """Env steps/s of all processes together, ``steps_each`` per process."""
        t0 = time.perf_counter()
        for c in self._conns:
            c.send(int(steps_each))
        for c in self._conns:
            c.recv()
        return steps_each * self.num_envs / (time.perf_counter() - t0)

    def close(self):
        for c in self._conns:
            try:
                c.send(None)
            except OSError:
                pass
        for p in self._procs:
            p.join(5)
            if p.is_alive():
                p.kill()


class UniformPolicy:
    """A picklable random policy for :meth:`SurgSimVectorEnv.rollout`: the other contenders' actions
    (:func:`~surgsim_envs.bench.random_actions.random_actions`: uniform in [-1, 1], Palpation's "report" at -1)."""

    def __init__(self, action_space, palpation: bool = False, seed: int = 0):
        self.space, self.palpation = action_space, bool(palpation)
        self.rng = np.random.default_rng(seed)

    def reset(self, seed=None):
        """A new stream (``SurgSimVectorEnv.rollout(..., seed=)`` gives each worker its own)."""
        self.rng = np.random.default_rng(seed)

    def __call__(self, obs):
        return random_actions(self.space, len(obs), self.rng, self.palpation)


class RolloutRun:
    """Our vector env driven by :meth:`SurgSimVectorEnv.rollout` with a :class:`UniformPolicy`: each
    worker steps its block ``steps_each`` times on one command (no round trip per step)."""

    def __init__(self, vec, palpation: bool = False):
        self.vec, self.num_envs = vec, vec.num_envs
        self.worker_pids = vec.worker_pids
        self.policy = UniformPolicy(vec.single_action_space, palpation)
        self._runs = 0

    def reset(self, seed=None):
        return self.vec.reset(seed=seed)

    def run(self, steps_each: int) -> float:
        self._runs += 1
        t0 = time.perf_counter()
        self.vec.rollout(self.policy, int(steps_each), seed=1000 * self._runs)
        return steps_each * self.num_envs / (time.perf_counter() - t0)

    def close(self):
        self.vec.close()


def _runs_itself(env) -> bool:
    """A contender that times its own run of ``steps_each`` env steps per env (``run``), without actions
    from :func:`alternate`: :class:`IndependentProcesses`, :class:`RolloutRun`."""
    return isinstance(env, (IndependentProcesses, RolloutRun))


def worker_pids(env) -> list:
    """Process ids of a vector env's workers (ours or Gymnasium's AsyncVectorEnv); [] otherwise."""
    if hasattr(env, "worker_pids"):
        return list(env.worker_pids)
    return [p.pid for p in getattr(env, "processes", [])]


def cpu_ns(pids) -> int:
    """Sum of the time on CPU (ns) of the main threads of ``pids`` (/proc/<pid>/schedstat)."""
    total = 0
    for pid in pids:
        with open(f"/proc/{pid}/schedstat") as f:
            total += int(f.read().split()[0])
    return total


def _timed(run, env, acts) -> tuple:
    """``(env steps/s, this process's CPU us per env step, the workers' CPU us per env step)``."""
    pids = worker_pids(env)
    try:
        w0 = cpu_ns(pids)
    except OSError:                          # no /proc (not Linux): no worker CPU figure
        pids, w0 = [], 0
    c0 = time.process_time()
    rate = run(env, acts)
    main_us = time.process_time() - c0
    steps = len(acts) * getattr(env, "num_envs", 1)
    worker_us = (cpu_ns(pids) - w0) * 1e-3 / steps if pids else float("nan")
    return rate, main_us * 1e6 / steps, worker_us


def alternate(contenders: dict, steps: int, repeats: int, palpation: bool = False, seed: int = 0) -> dict:
    """``contenders``: name -> an env (``num_envs`` absent: one env in this process) or a vector
    env. Warms each up, then ``repeats`` rounds, each timing every contender for ``steps`` env
    steps in turn. Returns per name the median env steps/s, and per vector contender
    ``<name>_speedup``: the median over rounds of its rate over the single env's in the same
    round (the first contender without ``num_envs`` is the single env); with a ``one_process_n<n>``
    contender also ``<name>_over_one_process`` (:func:`over_one_process`)."""
    rng = np.random.default_rng(seed)
    single = next(k for k, e in contenders.items() if not hasattr(e, "num_envs"))
    for name, env in contenders.items():
        env.reset(seed=seed)
        if _runs_itself(env):
            env.run(10)
        elif hasattr(env, "num_envs"):
            _run_vector(env, random_actions(env.action_space, 10, rng, palpation))
        else:
            _run_single(env, random_actions(env.action_space, 10, rng, palpation))
    rates = {k: [] for k in contenders}
    main_cpu = {k: [] for k in contenders}
    worker_cpu = {k: [] for k in contenders}
    for _ in range(repeats):
        for name, env in contenders.items():
            if _runs_itself(env):
                r, m, w = _timed(_run_vector, env, range(max(1, steps // env.num_envs)))
            elif hasattr(env, "num_envs"):
                acts = random_actions(env.action_space, max(1, steps // env.num_envs), rng, palpation)
                r, m, w = _timed(_run_vector, env, acts)
            else:
                r, m, w = _timed(_run_single, env, random_actions(env.action_space, steps, rng, palpation))
            rates[name].append(r)
            main_cpu[name].append(m)
            worker_cpu[name].append(w)
    med = statistics.median
    out = {f"{k}_steps_per_s": med(v) for k, v in rates.items()}
    out.update({f"{k}_main_cpu_us_per_env_step": med(v) for k, v in main_cpu.items()})
    out.update({f"{k}_worker_cpu_us_per_env_step": med(v) for k, v in worker_cpu.items() if k != single})
    for k, v in rates.items():
        if k != single:
            out[f"{k}_speedup"] = med(a / b for a, b in zip(v, rates[single]))
    for k in rates:
        if k.startswith("one_process_n"):
            out.update(over_one_process(rates, int(k[len("one_process_n"):])))
    return out


def _close_all(contenders: dict) -> None:
    for env in contenders.values():
        env.close()


#: numbers of envs timed, as multiples of the worker count (2 workers: 2, 4 and 8 envs)
ENV_MULTIPLES = (1, 2, 4)


def env_counts(workers: int, counts=None) -> tuple:
    """The numbers of envs timed: ``counts`` (a sequence of ints >= ``workers``), or ENV_MULTIPLES x workers."""
    if counts is None:
        return tuple(m * workers for m in ENV_MULTIPLES)
    ns = tuple(int(n) for n in counts)
    if not ns or any(n < workers for n in ns):
        raise ConfigError(f"--vector-envs needs env counts >= --workers ({workers}), got {list(counts)!r}")
    return ns


def contender_names(workers: int, counts=None) -> tuple:
    """The vector contenders' names, in table order: ``workers`` independent processes with one env
    each (``independent``, the ceiling), AsyncVectorEnv(workers envs), ours with ``n`` envs on
    ``workers`` processes (``vector_n<n>``), ours with the main process stepping one block
    (``in_main_n<n>``: ``workers - 1`` worker processes), for the fewest and the most envs, the most
    envs driven by :meth:`SurgSimVectorEnv.rollout` (``rollout_n<n>``: a random policy in the workers),
    and the most envs all stepped by this process (``one_process_n<n>``: ours with ``workers=1,
    in_main=True``, the same envs, packing and merge with no other process: the one-process baseline
    of :func:`over_one_process`)."""
    ns = env_counts(workers, counts)
    return ("independent", "async", *(f"vector_n{n}" for n in ns), f"in_main_n{ns[0]}", f"in_main_n{ns[-1]}",
            f"rollout_n{ns[-1]}", f"one_process_n{ns[-1]}")


def _ours(make, workers: int, counts=None, palpation: bool = False) -> dict:
    ns = env_counts(workers, counts)
    out = {f"vector_n{n}": make(n, in_main=False) for n in ns}
    out.update({f"in_main_n{n}": make(n, in_main=True) for n in dict.fromkeys((ns[0], ns[-1]))})
    out[f"rollout_n{ns[-1]}"] = RolloutRun(make(ns[-1], in_main=False), palpation)
    out[f"one_process_n{ns[-1]}"] = make(ns[-1], in_main=True, workers=1)
    return out


def over_one_process(rates: dict, n: int) -> dict:
    """Per contender with ``n`` envs on several processes (``vector_n<n>``, ``in_main_n<n>``,
    ``rollout_n<n>``): the median over rounds of its rate over ``one_process_n<n>``'s in the same round,
    as ``<name>_over_one_process``. ``rates``: name -> the rounds' env steps/s. This is the speed-up a
    user gets from the workers for the same ``n`` envs (the same round-robin over ``n`` envs, the same
    packing and info merge, in one process or in several); ``<name>_speedup`` is over a single env."""
    base = rates.get(f"one_process_n{n}")
    if not base:
        return {}
    return {f"{k}_over_one_process": statistics.median(a / b for a, b in zip(v, base))
            for k, v in rates.items() if k in (f"vector_n{n}", f"in_main_n{n}", f"rollout_n{n}")}


def task_contenders(env_id: str, workers: int, spin_us: float = 0.0, worker_spin_us: float = 0.0,
                    counts=None) -> dict:
    """One env, ``workers`` independent processes, AsyncVectorEnv(workers envs) and
    :class:`SurgSimVectorEnv` with each number of envs in ``counts`` on ``workers`` processes, and with
    ``in_main`` (see :func:`contender_names`)."""
    import gymnasium as gym

    single = gym.make(env_id)            # first: the workers fork a process that has loaded the task

    def make(n, in_main, workers=workers):
        return gym.make_vec(env_id, num_envs=n, workers=workers, in_main=in_main, spin_us=spin_us,
                            worker_spin_us=worker_spin_us, timeout_s=STEP_TIMEOUT)
    return {"single": single, "independent": IndependentProcesses(env_id, workers, "Palpation" in env_id),
            "async": gym.make_vec(env_id, num_envs=workers, vectorization_mode="async"),
            **_ours(make, workers, counts, "Palpation" in env_id)}


def spin_contenders(step_us: float, info: dict | None, workers: int, spin_us: float = 0.0,
                    worker_spin_us: float = 0.0, counts=None) -> dict:
    """The same with :class:`~surgsim_envs.bench.spin_env.SpinEnv` (busy-waits ``step_us``,
    returns a deep copy of ``info``)."""
    from gymnasium.vector import AsyncVectorEnv

    from surgsim_envs.vector import SurgSimVectorEnv

    env = functools.partial(SpinEnv, step_us, info)

    def make(n, in_main, workers=workers):
        return SurgSimVectorEnv(env, n, workers=workers, in_main=in_main, spin_us=spin_us,
                                worker_spin_us=worker_spin_us, timeout_s=STEP_TIMEOUT)
    return {"single": env(), "independent": IndependentProcesses(env, workers),
            "async": AsyncVectorEnv([env] * workers), **_ours(make, workers, counts)}


def vector_compare(env_id: str, workers: int, steps: int, repeats: int, spin_us=(), info: dict | None = None,
                   poll_us: float = 0.0, worker_poll_us: float = 0.0, counts=None) -> dict:
    """The task's alternating comparison, then the busy-wait stand-in's for each step time in
    ``spin_us`` (us; with the task's ``info``). ``poll_us``/``worker_poll_us``: our vector env's
    ``spin_us``/``worker_spin_us``; ``counts``: numbers of envs (default ENV_MULTIPLES x workers). Keys:
    ``vector_<name>_steps_per_s``, ``vector_<name>_speedup`` and ``spin<us>_<name>_...``;
    ``load_avg_1min`` before and after."""
    out = {"vector_workers": workers, "vector_spin_us": poll_us, "vector_worker_spin_us": worker_poll_us,
           "vector_env_counts": list(env_counts(workers, counts)), "load_avg_1min_before": os.getloadavg()[0]}
    contenders = task_contenders(env_id, workers, poll_us, worker_poll_us, counts)
    try:
        res = alternate(contenders, steps, repeats, palpation="Palpation" in env_id)
    finally:
        _close_all(contenders)
    out.update({f"vector_{k}": v for k, v in res.items()})
    for us in spin_us:
        contenders = spin_contenders(float(us), info, workers, poll_us, worker_poll_us, counts)
        try:
            res = alternate(contenders, steps, repeats)
        finally:
            _close_all(contenders)
        out.update({f"spin{us:.0f}_{k}": v for k, v in res.items()})
    out["load_avg_1min_after"] = os.getloadavg()[0]
    return out


# --- the per-step signal: options measured on this machine ------------------------------------
def _echo_pipe(rfd, wfd):
    while True:
        b = os.read(rfd, 1)
        if not b or b == b"q":
            return
        os.write(wfd, b"\0")


def _echo_eventfd(a, b):
    while True:
        if os.eventfd_read(a) > 1:          # main writes 2 to stop
            return
        os.eventfd_write(b, 1)


def _echo_semaphore(a, b):
    while a.acquire(timeout=60):
        b.release()


def _echo_connection(r, w):
    while True:
        try:
            m = r.recv_bytes()
        except EOFError:
            return
        if m == b"q":
            return
        w.send_bytes(b"\0")


def signal_roundtrip(workers: int, n: int = 5000, repeats: int = 5, context: str | None = None) -> dict:
    """Median us of one signal round trip to ``workers`` echo processes and back (all signalled,
    then all awaited), for one byte on an ``os.pipe``, a pair of ``os.eventfd`` counters, a pair of
    ``multiprocessing.Semaphore`` and
    ``multiprocessing.Connection.send_bytes``/``recv_bytes``. Blocking waits only (no busy-wait)."""
    import multiprocessing as mp

    ctx = mp.get_context(context or "fork")
    out = {}
    kinds = ("pipe_byte", "eventfd", "semaphore", "connection") if hasattr(os, "eventfd") else (
        "pipe_byte", "semaphore", "connection")
    for kind in kinds:
        procs, ends = [], []
        for _ in range(workers):
            if kind == "pipe_byte":
                r1, w1 = os.pipe()
                r2, w2 = os.pipe()
                p = ctx.Process(target=_echo_pipe, args=(r1, w2), daemon=True)
                p.start()
                os.close(r1)
                os.close(w2)
                ends.append((w1, r2))
            elif kind == "eventfd":
                a, b = os.eventfd(0), os.eventfd(0)
                p = ctx.Process(target=_echo_eventfd, args=(a, b), daemon=True)
                p.start()
                ends.append((a, b))
            elif kind == "semaphore":
                a, b = ctx.Semaphore(0), ctx.Semaphore(0)
                p = ctx.Process(target=_echo_semaphore, args=(a, b), daemon=True)
                p.start()
                ends.append((a, b))
            else:
                r1, w1 = ctx.Pipe(duplex=False)
                r2, w2 = ctx.Pipe(duplex=False)
                p = ctx.Process(target=_echo_connection, args=(r1, w2), daemon=True)
                p.start()
                ends.append((w1, r2))
            procs.append(p)

        if kind == "pipe_byte":
            def once():
                for w, _ in ends:
                    os.write(w, b"\1")
                for _, r in ends:
                    os.read(r, 1)
        elif kind == "eventfd":
            def once():
                for a, _ in ends:
                    os.eventfd_write(a, 1)
                for _, b in ends:
                    os.eventfd_read(b)
        elif kind == "semaphore":
            def once():
                for a, _ in ends:
                    a.release()
                for _, b in ends:
                    b.acquire()
        else:
            def once():
                for w, _ in ends:
                    w.send_bytes(b"\1")
                for _, r in ends:
                    r.recv_bytes()
        try:
            for _ in range(200):
                once()
            times = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                for _ in range(n):
                    once()
                times.append((time.perf_counter() - t0) / n * 1e6)
            out[f"{kind}_roundtrip_us"] = statistics.median(times)
        finally:
            for p in procs:
                p.kill()
                p.join(2)
            if kind in ("pipe_byte", "eventfd"):
                for w, r in ends:
                    os.close(w)
                    os.close(r)
    return out
