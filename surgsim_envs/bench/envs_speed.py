"""``surgsim bench envs``: Gymnasium env steps per second per task.

Single process, default task settings (control rate, physics dt and substeps are reported),
random actions (Palpation's "report" component held at -1 so episodes run to the time limit),
episode resets included. ``overhead_ratio``: wall time of one physics substep inside the env over
the tissue model's own ``step`` time for the same tissue and forces, same process. Then ``gym.make_vec(..., vectorization_mode="async")`` with
``--workers`` processes (default 2) for the scaling figure. Every figure is the median over
``--repeats`` timed runs of ``--steps`` env steps each (after a warm-up that compiles numba).
After each timed run a fixed reference kernel is timed (bench/reference_kernel.py):
``reference_kernel_us`` (median) and ``env_step_in_reference_kernels`` (the median env step over it),
a figure that a slow minute of the shared host moves less than the step time itself.
``default_over_plain``: the task's default env step over the same task on the plain ``mass_spring``
network, the two stepped alternately in this process (bench/default_model_cost.py;
``--no-model-ratio`` skips it).
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import statistics
import time

import numpy as np

from surgsim_envs.bench.random_actions import random_actions
from surgsim_envs.bench.reference_kernel import reference_kernel_us
from surgsim_envs.bench.spin_env import SpinEnv
from surgsim_envs import validate
from surgsim_envs.errors import ConfigError

#: s, an async step that takes longer than this raises instead of hanging
STEP_TIMEOUT = 60.0


def add_arguments(parser) -> None:
    parser.add_argument("--tasks", default="all", help="comma-separated task ids or 'all'")
    parser.add_argument("--steps", type=int, default=400, help="env steps per timed run (default 400)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per figure; median reported (default 3)")
    parser.add_argument("--workers", type=int, default=2, help="async vector env size (0 to skip; default 2)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.add_argument("--env-options", default=None,
                        help="a JSON object of gym.make keyword arguments for the single-env figures, e.g. "
                             "'{\"model\": \"fem_static\", \"spacing\": 0.0033333}' (a task's non-default model "
                             "and resolution: random actions with their resets, the cost an RL loop meets)")
    parser.add_argument("--compiled-vs-generic", action="store_true",
                        help="also time, alternately in this process, env steps and physics substeps with the "
                             "compiled substeps (scene/step/compiled.py) and with the generic per-substep loop")
    parser.add_argument("--async-baseline", action="store_true",
                        help="also time gym's AsyncVectorEnv with a trivial env and with envs that spin for this "
                             "task's measured env-step time (the pipe round-trip against ours), the same with the "
                             "task's info dict, the main process's info merge, and our envs wrapped in "
                             "InfoKeys(keys=('is_success',))")
    parser.add_argument("--vector", action="store_true",
                        help="also time, alternately in rounds, one env, gym's AsyncVectorEnv and our SurgSimVectorEnv "
                             "(gym.make_vec's default; --workers envs, 2 x --workers envs on the same workers, and "
                             "--workers envs with one block in the main process), "
                             "for the task and for busy-wait stand-ins (bench/vector_speed.py)")
    parser.add_argument("--spin-us", default="task,300",
                        help="with --vector: stand-in step times, us, comma-separated; 'task' = the task's measured "
                             "step time (default 'task,300')")
    parser.add_argument("--vector-spin-us", type=float, default=0.0,
                        help="with --vector: our vector env's spin_us (the main process polls this long for the "
                             "last replies before it sleeps; default 0)")
    parser.add_argument("--vector-worker-spin-us", type=float, default=0.0,
                        help="with --vector/--vector-accounting: our vector env's worker_spin_us (a worker polls "
                             "this long for its next command before it sleeps; default 0)")
    parser.add_argument("--vector-envs", default=None,
                        help="with --vector: numbers of envs for our vector env, comma-separated, each >= --workers "
                             "(default 1, 2 and 4 x --workers); with --vector-accounting: its env counts (default 1 "
                             "and 4 x --workers)")
    parser.add_argument("--vector-accounting", action="store_true",
                        help="where the time of one vector step goes (main-process phases, worker wake-up, env "
                             "step, packing, reply) for 1 and 4 envs per worker, tasks and a 300 us stand-in "
                             "(bench/vector_accounting.py)")
    parser.add_argument("--vector-only", action="store_true",
                        help="with --vector: skip the single-process figures except the step time")
    parser.add_argument("--signal-options", action="store_true",
                        help="also time the per-step signal options for --workers processes (pipe byte, "
                             "semaphore pair, multiprocessing Connection)")
    parser.add_argument("--no-model-ratio", action="store_true",
                        help="skip the task's default env step against the same task on the plain mass_spring "
                             "network, stepped alternately in this process (bench/default_model_cost.py)")


def parse_env_options(text) -> dict:
    """``--env-options``: a JSON object of gym.make keyword arguments ({} for None)."""
    if text is None:
        return {}
    try:
        opts = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConfigError(f"--env-options {text!r} is not JSON ({exc}); pass an object such as "
                          '\'{"model": "fem_static", "spacing": 0.005}\'') from None
    if not isinstance(opts, dict):
        raise ConfigError(f"--env-options {text!r} must be a JSON object of gym.make keyword arguments, "
                          '{"model": "fem_static"}')
    return opts


def single_rate(env_id: str, steps: int, repeats: int, compiled_vs: bool = False, env_options=None) -> dict:
    """Median env steps/s of one env in this process, plus its timing settings; ``env_options``:
    gym.make keyword arguments (default: the task's defaults)."""
    import gymnasium as gym

    env = gym.make(env_id, **(env_options or {}))
    u = env.unwrapped
    rng = np.random.default_rng(0)
    pal = "Palpation" in env_id
    env.reset(seed=0)
    for a in random_actions(env.action_space, 20, rng, pal):
        env.step(a)
    rates, physics_rates, refs = [], [], []
    for r in range(repeats):
        acts = random_actions(env.action_space, steps, rng, pal)
        env.reset(seed=r)
        physics = 0
        t0 = time.perf_counter()
        for a in acts:
            before = u.sim.steps
            _, _, term, trunc, _ = env.step(a)
            physics += u.sim.steps - before      # physics steps actually taken (a press task takes many)
            if term or trunc:
                env.reset()
        wall = time.perf_counter() - t0
        rates.append(steps / wall)
        physics_rates.append(physics / wall)
        refs.append(reference_kernel_us(calls=100, repeats=1))   # the host's state beside this run
    substep_us, tissue_us = overhead(env, steps, repeats, rng, pal)
    step1_us, step1_flex_us = visual_flex_cost(u.sim, repeats)
    t0 = time.perf_counter()
    for r in range(5):
        env.reset(seed=r)
    reset_ms = (time.perf_counter() - t0) / 5 * 1e3
    out = {"task": env_id, "steps_per_s": statistics.median(rates), "control_hz": u.config.control_hz,
           "physics_dt_s": u.sim.dt, "substeps": u.substeps, "tissue_nodes": int(u.sim.tissue().n_nodes),
           "reset_ms": reset_ms, "physics_steps_per_s": statistics.median(physics_rates),
           "physics_steps_per_env_step": statistics.median(physics_rates) / statistics.median(rates),
           "substep_us": substep_us, "tissue_step_us": tissue_us, "overhead_ratio": substep_us / tissue_us,
           "mj_step1_us": step1_us, "mj_step1_with_visual_flex_us": step1_flex_us,
           "reference_kernel_us": statistics.median(refs),
           "env_step_in_reference_kernels": 1e6 / statistics.median(rates) / statistics.median(refs),
           "load_avg_1min": os.getloadavg()[0], "tissue_model": u.sim.tissue().name}
    out["compiled_substeps"] = u.sim.compiled_runner() is not None
    if compiled_vs:
        out.update(compiled_vs_generic(env, repeats, rng, pal, steps))
    env.close()
    return out


def overhead(env, steps: int, repeats: int, rng, palpation: bool) -> tuple[float, float]:
    """``(substep_us, tissue_step_us)``: median wall time of one physics substep inside the env (an
    env step divided by the physics steps it took (counted by the simulation), so every cost of the
    env is in it) and of the tissue model's
    own ``step`` on a copy of the same tissue under the same contact forces and stiffness, timed
    alternately in this process (same load). Their ratio is ``overhead_ratio``."""
    import copy

    u = env.unwrapped
    sub, own = [], []
    n = max(1, steps // 4)
    for _ in range(repeats):
        env.reset(seed=int(rng.integers(2**31)))
        acts = random_actions(env.action_space, n, rng, palpation)
        first = u.sim.steps
        t0 = time.perf_counter()
        for a in acts:
            _, _, term, trunc, _ = env.step(a)
            if term or trunc:
                break
        k = max(1, u.sim.steps - first)     # physics steps taken (counted, not assumed = substeps)
        sub.append((time.perf_counter() - t0) / k * 1e6)
        sim = u.sim
        name = next(iter(sim.contacts))
        try:
            tissue = copy.deepcopy(sim.tissues[name])
        except TypeError:        # a model holding a factorisation (fem_static's SuperLU) cannot be copied
            own.append(float("nan"))
            continue
        res = sim.contacts[name].result
        forces = np.array(res.forces)
        stiffness = None if res.stiffness is None else np.array(res.stiffness)
        t0 = time.perf_counter()
        for _ in range(k):
            tissue.step(sim.dt, forces, stiffness)
        own.append((time.perf_counter() - t0) / k * 1e6)
    own = [t for t in own if t == t]
    return statistics.median(sub), (statistics.median(own) if own else float("nan"))


def compiled_vs_generic(env, repeats: int, rng, palpation: bool, steps: int, n: int = 300) -> dict:
    """Median wall time of an env step (``steps // 4`` random actions from a reset) and of one
    physics substep (``n`` substeps from the state the actions left), with the compiled substeps
    and with the generic loop, alternately in this process (same load); also the env step's CPU
    time of this thread (``time.thread_time``), which a shared machine inflates less than wall time."""
    u = env.unwrapped
    sim = u.sim
    env_us = {True: [], False: []}
    env_cpu_us = {True: [], False: []}
    sub_us = {True: [], False: []}
    k = max(1, steps // 4)
    try:
        for r in range(repeats):
            for compiled in (True, False):
                sim.compiled_substeps = compiled
                env.reset(seed=r)
                acts = random_actions(env.action_space, k, rng, palpation)
                taken = 0
                c0 = time.thread_time()
                t0 = time.perf_counter()
                for a in acts:
                    _, _, term, trunc, _ = env.step(a)
                    taken += 1
                    if term or trunc:
                        break
                env_us[compiled].append((time.perf_counter() - t0) / taken * 1e6)
                env_cpu_us[compiled].append((time.thread_time() - c0) / taken * 1e6)
                t0 = time.perf_counter()
                sim.physics_step(n)
                sub_us[compiled].append((time.perf_counter() - t0) / n * 1e6)
    finally:
        sim.compiled_substeps = True
    med = statistics.median
    return {"compiled_env_step_us": med(env_us[True]), "generic_env_step_us": med(env_us[False]),
            "compiled_env_step_cpu_us": med(env_cpu_us[True]), "generic_env_step_cpu_us": med(env_cpu_us[False]),
            "compiled_substep_us": med(sub_us[True]), "generic_substep_us": med(sub_us[False]),
            "generic_over_compiled_env_step": med(env_us[False]) / med(env_us[True]),
            "generic_over_compiled_substep": med(sub_us[False]) / med(sub_us[True])}


def _spin_env(step_us: float, info: dict | None = None):
    return SpinEnv(step_us, info)


def task_info(env_id: str) -> dict:
    """The info dict of one random step of task ``env_id`` (what every step sends through the pipe)."""
    import gymnasium as gym

    env = gym.make(env_id)
    try:
        env.reset(seed=0)
        return env.step(env.action_space.sample())[4]
    finally:
        env.close()


def info_merge_us(info: dict, workers: int, repeats: int, n: int = 500) -> float:
    """us the main process of a vector env spends merging ``workers`` step infos like ``info``
    (Gymnasium's ``VectorEnv._add_info``, run once per env per vector step, serially)."""
    from gymnasium.vector import SyncVectorEnv

    vec = SyncVectorEnv([SpinEnv] * workers)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(n):
            merged = {}
            for k in range(workers):
                merged = vec._add_info(merged, info, k)
        times.append((time.perf_counter() - t0) / n * 1e6)
    vec.close()
    return statistics.median(times)


def async_baseline(workers: int, steps: int, repeats: int, step_us: float, info: dict | None = None) -> dict:
    """Steps/s of one SpinEnv(step_us) in this process and of ``workers`` of them in gym's
    AsyncVectorEnv, and the async round-trip overhead per vector step (us) with step_us = 0; with
    ``info`` (a task's step info) also the async speed-up of spin envs that return it and the
    main process's time to merge the workers' infos."""
    import functools

    from gymnasium.vector import AsyncVectorEnv

    def rate_single(us, info=None):
        env = SpinEnv(us, info)
        env.reset(seed=0)
        a = np.zeros(4, np.float32)
        rates = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            for _ in range(steps):
                env.step(a)
            rates.append(steps / (time.perf_counter() - t0))
        return statistics.median(rates)

    def rate_async(us, info=None):
        vec = AsyncVectorEnv([functools.partial(_spin_env, us, info)] * workers)
        try:
            vec.reset(seed=0)
            a = np.zeros((workers, 4), np.float32)
            for _ in range(10):
                vec.step(a)
            rates = []
            n = max(1, steps // workers)
            for _ in range(repeats):
                t0 = time.perf_counter()
                for _ in range(n):
                    vec.step(a)
                rates.append(n * workers / (time.perf_counter() - t0))
        finally:
            vec.close()
        return statistics.median(rates)

    trivial = rate_async(0.0)
    single, multi = rate_single(step_us), rate_async(step_us)
    out = {"async_trivial_steps_per_s": trivial, "async_roundtrip_us": workers / trivial * 1e6,
           "spin_step_us": step_us, "spin_single_steps_per_s": single, "spin_async_steps_per_s": multi,
           "spin_async_speedup": multi / single}
    if info:
        trivial_info = rate_async(0.0, info)
        single_info, multi_info = rate_single(step_us, info), rate_async(step_us, info)
        out.update(async_roundtrip_with_info_us=workers / trivial_info * 1e6,
                   spin_info_async_speedup=multi_info / single_info,
                   info_merge_us=info_merge_us(info, workers, repeats))
    return out


def visual_flex_cost(sim, repeats: int, n: int = 500) -> tuple[float, float]:
    """``(us, us)``: median ``mj_step1`` of the physics model (no flex) and of the render twin (the
    same model plus the tissue surface flexes, as every physics step paid before the twin),
    timed alternately on copies of the current state in this process."""
    import mujoco

    sim.sync_visual()
    models = [(sim.model, mujoco.MjData(sim.model)), (sim.render_model, mujoco.MjData(sim.render_model))]
    for m, d in models:
        d.qpos[:] = sim.data.qpos
        mujoco.mj_forward(m, d)
    times = ([], [])
    for _ in range(repeats):
        for k, (m, d) in enumerate(models):
            t0 = time.perf_counter()
            for _ in range(n):
                mujoco.mj_step1(m, d)
            times[k].append((time.perf_counter() - t0) / n * 1e6)
    return statistics.median(times[0]), statistics.median(times[1])


def async_rate(env_id: str, workers: int, steps: int, repeats: int, info_keys=None) -> float:
    """Median total env steps/s of an async vector env with ``workers`` processes; ``info_keys``:
    wrap each env in :class:`~surgsim_envs.envs.wrappers.InfoKeys` with these keys."""
    import functools

    import gymnasium as gym

    from surgsim_envs.envs.wrappers import InfoKeys

    wrappers = None if info_keys is None else [functools.partial(InfoKeys, keys=tuple(info_keys))]
    vec = gym.make_vec(env_id, num_envs=workers, vectorization_mode="async", wrappers=wrappers)
    rng = np.random.default_rng(0)
    pal = "Palpation" in env_id
    try:
        vec.reset(seed=list(range(workers)))
        for a in random_actions(vec.action_space, 10, rng, pal):
            vec.step_async(a)
            vec.step_wait(timeout=STEP_TIMEOUT)
        rates = []
        n = max(1, steps // workers)
        for _ in range(repeats):
            acts = random_actions(vec.action_space, n, rng, pal)
            t0 = time.perf_counter()
            for a in acts:
                vec.step_async(a)
                vec.step_wait(timeout=STEP_TIMEOUT)
            rates.append(n * workers / (time.perf_counter() - t0))
    finally:
        vec.close()
    return statistics.median(rates)


def _model_ratio(env_id: str, steps: int, repeats: int) -> dict:
    """The task's default env step against the plain mass_spring network (bench/default_model_cost.py);
    ``model_ratio_error`` instead where the task cannot be built on that network."""
    from surgsim_envs.bench.default_model_cost import default_vs_plain
    from surgsim_envs.errors import SurgSimError

    try:
        return default_vs_plain(env_id, steps, repeats)
    except (SurgSimError, TypeError) as exc:
        return {"model_ratio_error": f"{type(exc).__name__}: {exc}"}


#: us, the longest stand-in step time or poll the vector figures take (a second per step is not a
#: stand-in for a task, and a timed run of it would take hours)
MAX_SPIN_US = 1e6


def _vector_envs_option(args):
    """``--vector-envs`` as a list of ints in [1, 1024] (None when not given); ConfigError naming a bad value."""
    counts = getattr(args, "vector_envs", None)
    if counts is None:
        return None
    try:
        out = [int(c) for c in str(counts).split(",") if c.strip()]
    except ValueError:
        raise ConfigError(f"--vector-envs takes env counts (integers), comma-separated, got {counts!r}") from None
    if not out or any(not 1 <= c <= 1024 for c in out):
        raise ConfigError(f"--vector-envs={counts!r}: each env count must lie in [1, 1024], e.g. 2,4,8")
    return out


def _spin_stand_ins(args) -> list:
    """``--spin-us`` as a list of 'task' or step times in us in (0, MAX_SPIN_US]; ConfigError naming a bad one."""
    out = []
    for s in str(args.spin_us).split(","):
        s = s.strip()
        if not s:
            continue
        if s == "task":
            out.append(s)
            continue
        try:
            v = float(s)
        except ValueError:
            raise ConfigError(f"--spin-us takes step times in us or 'task', got {s!r}") from None
        out.append(validate.real(v, "--spin-us", lo=0.0, hi=MAX_SPIN_US, lo_open=True, unit="us",
                                 fix=f"stand-in step times in (0, {MAX_SPIN_US:g}] us or 'task', e.g. task,300"))
    return out


def check_vector_args(args) -> None:
    """Validate the --vector options whether or not --vector is given (an option that is set is valid)."""
    _spin_stand_ins(args)
    _vector_envs_option(args)
    for key in ("vector_spin_us", "vector_worker_spin_us"):
        validate.real(getattr(args, key, 0.0), "--" + key.replace("_", "-"), lo=0.0, hi=MAX_SPIN_US, unit="us",
                      fix=f"a poll time in [0, {MAX_SPIN_US:g}] us, e.g. 0")


def vector_row(env_id: str, args, step_us: float | None = None) -> dict:
    """``--vector`` figures of one task (:func:`surgsim_envs.bench.vector_speed.vector_compare`)."""
    from surgsim_envs.bench.vector_speed import vector_compare

    if args.workers < 1:
        raise ConfigError(f"--vector needs --workers >= 1, got {args.workers}")
    spin = []
    for s in _spin_stand_ins(args):
        if s == "task":
            if step_us is None:
                step_us = 1e6 / single_rate_quick(env_id, args.steps, args.repeats)
            spin.append(step_us)
        else:
            spin.append(s)
    row = {"task": env_id, "task_step_us": step_us}
    counts = _vector_envs_option(args)
    row.update(vector_compare(env_id, args.workers, args.steps, args.repeats, spin, task_info(env_id),
                              poll_us=getattr(args, "vector_spin_us", 0.0),
                              worker_poll_us=getattr(args, "vector_worker_spin_us", 0.0), counts=counts))
    return row


def single_rate_quick(env_id: str, steps: int, repeats: int) -> float:
    """Median env steps/s of one env in this process (random actions, resets included)."""
    import gymnasium as gym

    from surgsim_envs.bench.vector_speed import alternate

    env = gym.make(env_id)
    try:
        return alternate({"single": env}, steps, repeats, palpation="Palpation" in env_id)["single_steps_per_s"]
    finally:
        env.close()


def _row_prefixes(r: dict) -> list:
    """``(key prefix, label)`` of a ``--vector`` row's comparisons: the task's, then each stand-in's."""
    return [("vector_", r["task"])] + [(k[: -len("single_steps_per_s")], f"  spin {k[4:].split('_')[0]} us")
                                       for k in r if k.startswith("spin") and k.endswith("single_steps_per_s")]


def print_vector(rows) -> None:
    """The ``--vector`` table: env steps/s and speed-up over one env, same rounds."""
    from surgsim_envs.bench.vector_speed import contender_names

    names = contender_names(rows[0]["vector_workers"], rows[0].get("vector_env_counts")) if rows else ()
    print(f"speed-up over one env, same rounds ({rows[0]['vector_workers'] if rows else '-'} workers; "
          "independent: that many processes, one env each, no exchange (the ceiling); "
          "vector_n<n>: n envs on them; in_main_n<n>: this process steps one block)")
    print(f"{'what':34s} {'1 env/s':>8s} " + " ".join(f"{n + ' x':>13s}" for n in names) + "   load before/after")
    for r in rows:
        for p, label in _row_prefixes(r):
            print(f"{label:34s} {r[p + 'single_steps_per_s']:8.0f} "
                  + " ".join(f"{r[p + n + '_speedup']:13.2f}" for n in names)
                  + f"   {r['load_avg_1min_before']:.1f}/{r['load_avg_1min_after']:.1f}")
    if not rows:
        return
    n = rows[0]["vector_env_counts"][-1]
    multi = (f"vector_n{n}", f"in_main_n{n}", f"rollout_n{n}")
    print(f"\nspeed-up over one process stepping the same {n} envs (one_process_n{n}: workers=1, in_main=True), "
          "same rounds")
    print(f"{'what':34s} " + " ".join(f"{m + ' x':>15s}" for m in multi))
    for r in rows:
        for p, label in _row_prefixes(r):
            print(f"{label:34s} " + " ".join(f"{r.get(p + m + '_over_one_process', float('nan')):15.2f}"
                                             for m in multi))


def _run_accounting(tasks, args) -> int:
    """``--vector-accounting``: per task and for a 300 us stand-in returning the first task's info."""
    from surgsim_envs.bench import vector_accounting as acc

    if args.workers < 1:
        raise ConfigError(f"--vector-accounting needs --workers >= 1, got {args.workers}")
    from surgsim_envs.bench.vector_speed import env_counts

    given = _vector_envs_option(args)
    counts = (args.workers, 4 * args.workers) if given is None else env_counts(args.workers, given)
    spin = getattr(args, "vector_spin_us", 0.0)
    wspin = getattr(args, "vector_worker_spin_us", 0.0)
    rows = []
    load0 = os.getloadavg()[0]
    for t in tasks:
        for r in acc.accounting_rows(t, counts, args.workers, args.steps, args.repeats, "Palpation" in t, spin_us=spin,
                                     worker_spin_us=wspin):
            rows.append({"what": t, **r})
    stand_in = functools.partial(SpinEnv, 300.0, task_info(tasks[0]))
    for r in acc.accounting_rows(stand_in, counts, args.workers, args.steps, args.repeats, spin_us=spin,
                                 worker_spin_us=wspin):
        rows.append({"what": "stand-in 300 us", **r})
    out = {"vector_accounting": rows, "load_avg_1min_before": load0, "load_avg_1min_after": os.getloadavg()[0]}
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        acc.print_rows(rows)
        print(f"load average (1 min) before/after: {load0:.1f}/{out['load_avg_1min_after']:.1f}")
    return 0


#: env steps one timed run may take
MAX_BENCH_STEPS = 1_000_000


def run(args) -> int:
    import surgsim_envs  # noqa: F401
    from surgsim_envs.envs import TASKS

    # the action arrays of a timed run are allocated up front: 10^12 steps asked for 29 TiB
    validate.integer(args.steps, "--steps", lo=1, hi=MAX_BENCH_STEPS,
                     fix=f"env steps per timed run, at most {MAX_BENCH_STEPS:,} (their actions are allocated up front)")
    validate.integer(args.repeats, "--repeats", lo=1, hi=100, fix="timed runs per figure, e.g. 3")
    validate.integer(args.workers, "--workers", lo=0, hi=1024, fix="async vector env size, 0 to skip")
    check_vector_args(args)
    tasks = list(TASKS) if args.tasks == "all" else [t.strip() for t in args.tasks.split(",")]
    unknown = [t for t in tasks if t not in TASKS]
    if unknown:
        raise ConfigError(f"unknown task(s) {unknown}; known: {list(TASKS)}")
    if getattr(args, "vector_accounting", False):
        return _run_accounting(tasks, args)
    if parse_env_options(getattr(args, "env_options", None)) and (
            args.workers or getattr(args, "vector", False) or not getattr(args, "no_model_ratio", False)):
        raise ConfigError("--env-options times the single env only; add --workers 0 --no-model-ratio (the vector "
                          "and model-ratio figures build the task's defaults)")
    rows = []
    vector = getattr(args, "vector", False)
    for t in tasks:
        if vector and getattr(args, "vector_only", False):
            row = vector_row(t, args)
            rows.append(row)
            continue
        env_options = parse_env_options(getattr(args, "env_options", None))
        row = single_rate(t, args.steps, args.repeats, getattr(args, "compiled_vs_generic", False), env_options)
        if env_options:
            row["env_options"] = env_options
        if not getattr(args, "no_model_ratio", False):
            row.update(_model_ratio(t, args.steps, args.repeats))
        if vector:
            row.update(vector_row(t, args, 1e6 / row["steps_per_s"]))
        if args.workers:
            row["async_workers"] = args.workers
            row["async_steps_per_s"] = async_rate(t, args.workers, args.steps, args.repeats)
            row["async_speedup"] = row["async_steps_per_s"] / row["steps_per_s"]
            if getattr(args, "async_baseline", False):
                row.update(async_baseline(args.workers, args.steps, args.repeats, 1e6 / row["steps_per_s"],
                                          task_info(t)))
                row["async_info_keys_steps_per_s"] = async_rate(t, args.workers, args.steps, args.repeats,
                                                                info_keys=("is_success",))
                row["async_info_keys_speedup"] = row["async_info_keys_steps_per_s"] / row["steps_per_s"]
        rows.append(row)
    out = {"envs": rows}
    if getattr(args, "signal_options", False):
        from surgsim_envs.bench.vector_speed import signal_roundtrip

        out["signal_options"] = {w: signal_roundtrip(w, repeats=args.repeats) for w in range(1, max(1, args.workers) + 1)}
        out["signal_options_load_avg_1min"] = os.getloadavg()[0]
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    if vector:
        print_vector(rows)
    if getattr(args, "signal_options", False):
        print(f"signal round trip, us: {out['signal_options']}")
    if not any("steps_per_s" in r for r in rows):
        return 0
    print(f"{'task':24s} {'steps/s':>8s} {'ctrl Hz':>8s} {'dt ms':>6s} {'sub':>4s} {'nodes':>6s} {'reset ms':>9s}"
          f" {'async/s':>8s} {'speedup':>8s} {'overhead':>8s} {'ref us':>7s} {'step/ref':>8s}"
          f" {'default us':>10s} {'plain us':>8s} {'def/plain':>9s}")
    for r in rows:
        if "steps_per_s" not in r:
            continue
        print(f"{r['task']:24s} {r['steps_per_s']:8.0f} {r['control_hz']:8.0f} {r['physics_dt_s'] * 1e3:6.2f} "
              f"{r['substeps']:4d} {r['tissue_nodes']:6d} {r['reset_ms']:9.1f} "
              f"{r.get('async_steps_per_s', float('nan')):8.0f} {r.get('async_speedup', float('nan')):8.2f} "
              f"{r['overhead_ratio']:8.2f} {r['reference_kernel_us']:7.1f} {r['env_step_in_reference_kernels']:8.2f} "
              f"{r.get('default_step_us', float('nan')):10.1f} {r.get('plain_step_us', float('nan')):8.1f} "
              f"{r.get('default_over_plain', float('nan')):9.2f}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    p = argparse.ArgumentParser(description=__doc__)
    add_arguments(p)
    raise SystemExit(run(p.parse_args()))
