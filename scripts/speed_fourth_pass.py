"""Measurements behind docs/benchmarks.md, "Env step: fourth pass (issue 18)". Thread CPU time
(steadier than wall time on a shared machine); run with ``MUJOCO_GL=egl`` and ``PYTHONPATH`` set to
the tree to measure.

    python scripts/speed_fourth_pass.py split [TASK ...]   # where one env step goes (Palpation, Grasp)
    python scripts/speed_fourth_pass.py cpu-step [N] [--tissue-model NAME]   # JSON: CPU us per env step

``split`` times, on the same env in the same process: the whole env step; the compiled call
(``runner.run``) and inside it the numba loop (``run_substeps``); one call of that loop with nothing
to do (count 0: the dispatch, i.e. unboxing its arguments); and, in numba loops on the env's own
state, MuJoCo's ``mj_step1`` + ``mj_step2``, the contact kernel, the symplectic tissue step and the
guard's per-step checks, each per call.
"""

from __future__ import annotations

import copy
import json
import sys
import time

import gymnasium as gym
import numpy as np
from numba import njit

import surgsim_envs  # noqa: F401
from surgsim_envs.contact.model import contact_kernel_prepared
from surgsim_envs.scene.mujoco_native import call_model_data
from surgsim_envs.tissue.guard import first_non_finite, max_speed_squared
from surgsim_envs.tissue.msd_kernels import symplectic_step_work

TASKS = ("SurgSim/Palpation-v0", "SurgSim/Grasp-v0")


def _actions(env, n, rng):
    a = rng.uniform(-1, 1, (n, env.action_space.shape[0])).astype(np.float32)
    if "Palpation" in env.spec.id:
        a[:, 2] = np.clip(a[:, 2], -1.0, 0.2) - 0.6   # mostly pressing: contact on most steps
        a[:, 3] = -1.0                                 # no report: the episode runs to the time limit
    return a


def _us_per_step(env, acts) -> float:
    """Thread CPU us per env step over ``acts`` (resetting at episode ends)."""
    t = time.thread_time_ns()
    for a in acts:
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    return (time.thread_time_ns() - t) / len(acts) / 1e3


@njit(cache=True)
def _mj_loop(n, step1, step2, m, d):
    for _ in range(n):
        call_model_data(step1, m, d)
        call_model_data(step2, m, d)


@njit(cache=True)
def _contact_loop(n, pos, vel, gpos, gmat, gvel, tcom, state):
    for _ in range(n):
        contact_kernel_prepared(pos, vel, gpos, gmat, gvel, tcom, state)


@njit(cache=True)
def _tissue_loop(n, st, fext, dt, work):
    (pos, vel, inv_mass, b0, gravity, fixed, si, sj, L0, K1, K2, kMg0, decay0, kMg, decay, s_state, dl_state, f_buf,
     tets, V0, kv) = st
    for _ in range(n):
        symplectic_step_work(pos, vel, inv_mass, b0, fext, gravity, fixed, dt, si, sj, L0, K1, K2, kMg, decay,
                             s_state, dl_state, f_buf, tets, V0, kv, work)


@njit(cache=True)
def _guard_loop(n, pos, vel, forces, stiffness):
    acc = 0.0
    for _ in range(n):
        acc += max_speed_squared(pos, vel)
        acc += first_non_finite(forces) + first_non_finite(stiffness)
    return acc


def _per_call_us(fn, n, reps=7):
    out = []
    for _ in range(reps):
        t = time.thread_time_ns()
        fn(n)
        out.append((time.thread_time_ns() - t) / n / 1e3)
    return float(np.median(out))


def split(task: str, steps: int = 300, tissue_model: str | None = None) -> dict:
    kw = {"model": tissue_model} if tissue_model else {}
    env = gym.make(task, **kw)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    for a in _actions(env, 30, rng):
        env.step(a)
    sim = env.unwrapped.sim
    runner = sim._compiled_runner()
    timers = {"run": 0, "kernel": 0, "dispatch": 0, "calls": 0}
    real_run = runner.run
    new_layout = hasattr(runner, "_loop")            # this tree (address table) or an older one
    if new_layout:
        real_kernel = runner._loop
    else:
        from surgsim_envs.scene import substeps_mass_spring as sms
        real_kernel = sms.run_substeps

    def timed_kernel(*args):
        t = time.thread_time_ns()
        out = real_kernel(*args)
        timers["kernel"] += time.thread_time_ns() - t
        t = time.thread_time_ns()
        if new_layout:     # count 0: returns at once -> the dispatch cost alone
            real_kernel(*args[:7], 0, 0, 0, *args[10:])
        else:
            real_kernel(0, 0, 0, *args[3:])
        timers["dispatch"] += time.thread_time_ns() - t
        timers["calls"] += 1
        return out

    def timed_run(*args, **kw):
        t = time.thread_time_ns()
        real_run(*args, **kw)
        timers["run"] += time.thread_time_ns() - t

    acts = _actions(env, steps, rng)
    # untimed pass for the total (no wrappers), then the instrumented pass
    totals = []
    for rep in range(3):
        env.reset(seed=rep)
        totals.append(_us_per_step(env, acts))
    runner.run = timed_run
    if new_layout:
        runner._loop = timed_kernel
    else:
        sms.run_substeps = timed_kernel
    try:
        env.reset(seed=0)
        t = time.thread_time_ns()
        for a in acts:
            _, _, term, trunc, _ = env.step(a)
            if term or trunc:
                env.reset()
        instrumented = (time.thread_time_ns() - t) / steps / 1e3
    finally:
        runner.run = real_run
        if new_layout:
            runner._loop = real_kernel
        else:
            sms.run_substeps = real_kernel
    per = {k: timers[k] / steps / 1e3 for k in ("run", "kernel", "dispatch")}
    # the dispatch call was timed inside "kernel" and "run" but is extra: take it out of both
    kernel = per["kernel"]
    run = per["run"] - per["dispatch"]
    n_sub = sim.substeps
    n_mj = n_sub // sim.tissue_subcycles
    # kernels alone, on copies of the env's state
    tissue, contact = sim._pairs[0]
    d2 = copy.copy(sim.data)
    fns = runner._fns
    mj = _per_call_us(lambda n: _mj_loop(n, fns[0], fns[1], int(sim.model._address), int(d2._address)), 200)
    st = tuple(np.array(a, copy=True) if isinstance(a, np.ndarray) else a for a in
               tissue.symplectic_kernel_state(sim.dt))
    fext = contact.result.forces.copy()
    work = np.empty((4, len(tissue.si)))
    tis = _per_call_us(lambda n: _tissue_loop(n, st, fext, sim.dt, work), 200)
    cst = tuple(np.array(a, copy=True) if isinstance(a, np.ndarray) else a for a in contact.kernel_state())
    pos, vel = tissue.positions.copy(), tissue.velocities.copy()
    con = _per_call_us(lambda n: _contact_loop(n, pos, vel, sim._gpos, sim._gmat, sim._gvel, sim._tcom, cst), 200)
    grd = _per_call_us(lambda n: _guard_loop(n, pos, vel, contact.result.forces, contact.result.stiffness), 200)
    contacts = int(contact.report.contacts.sum())
    env.close()
    total = float(np.median(totals))
    body = kernel - per["dispatch"]
    return {"task": task, "tissue_model": tissue_model or "default", "nodes": int(tissue.n_nodes),
            "springs": int(len(tissue.si)), "substeps": n_sub, "mujoco_steps": n_mj, "contacts_now": contacts,
            "env_step_us": total, "instrumented_env_step_us": instrumented,
            "env_python_us": total - run, "runner_python_us": run - kernel, "dispatch_us": per["dispatch"],
            "compiled_body_us": body, "per_substep_body_us": body / n_sub,
            "mj_step1_2_us": mj, "contact_kernel_us": con, "tissue_step_us": tis, "guard_checks_us": grd,
            "body_rest_per_substep_us": body / n_sub - (mj * n_mj / n_sub + con + tis + grd)}


def cpu_step(n: int = 300, tissue_model: str | None = None, tasks=("SurgSim/Palpation-v0", "SurgSim/Grasp-v0",
                                                                   "SurgSim/Slippage-v0")) -> None:
    out = {}
    kw = {"model": tissue_model} if tissue_model else {}
    for task in tasks:
        env = gym.make(task, **kw)
        rng = np.random.default_rng(0)
        env.reset(seed=0)
        for a in _actions(env, 20, rng):
            env.step(a)
        res = []
        for r in range(3):
            acts = _actions(env, n, rng)
            env.reset(seed=r)
            res.append(_us_per_step(env, acts))
        out[task] = float(np.median(res))
        env.close()
    print(json.dumps(out))


def main() -> None:
    cmd, args = (sys.argv[1] if len(sys.argv) > 1 else ""), sys.argv[2:]
    model = None
    if "--tissue-model" in args:
        i = args.index("--tissue-model")
        model = args[i + 1]
        args = args[:i] + args[i + 2:]
    if cmd == "split":
        for task in (args or TASKS):
            print(json.dumps({k: (round(v, 2) if isinstance(v, float) else v)
                              for k, v in split(task, tissue_model=model).items()}))
    elif cmd == "cpu-step":
        cpu_step(int(args[0]) if args else 300, model)
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main()
