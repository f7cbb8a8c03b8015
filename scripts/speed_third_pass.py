"""Measurements behind docs/benchmarks.md, "Env step: third pass (issue 18)". Thread CPU time
(steadier than wall time on a shared machine); run with ``MUJOCO_GL=egl`` and ``PYTHONPATH`` set to
the tree to measure (e.g. a ``git archive`` of main in /tmp/base, then this tree), alternately.

    python scripts/speed_third_pass.py kernel          # spring_forces vs spring_forces_passes, same process
    python scripts/speed_third_pass.py cpu-step [N]    # JSON: CPU us per env step per task (random actions)
    python scripts/speed_third_pass.py env-python      # env Python per step, physics stubbed out
    python scripts/speed_third_pass.py trajectory OUT.pkl   # obs, rewards, infos, tissue of random steps
    python scripts/speed_third_pass.py compare A.pkl B.pkl  # bit-for-bit comparison of two dumps
"""

from __future__ import annotations

import json
import pickle
import sys
import time

import gymnasium as gym
import numpy as np
from numba import njit

import surgsim_envs  # noqa: F401
from surgsim_envs.tissue import msd_kernels as kern

TASKS = ("SurgSim/Palpation-v0", "SurgSim/Grasp-v0", "SurgSim/Slippage-v0")


def _actions(env, n, rng):
    a = rng.uniform(-1, 1, (n, env.action_space.shape[0])).astype(np.float32)
    if "Palpation" in env.spec.id:
        a[:, 3] = -1.0                          # no report: episodes run to the time limit
    return a


def _cpu(fn, reps: int = 9) -> float:
    out = []
    for _ in range(reps):
        t = time.thread_time_ns()
        fn()
        out.append(time.thread_time_ns() - t)
    return float(np.median(out))


@njit(cache=True)
def _loop_single(n, pos, si, sj, L0, K1, K2, kMg, dec, s, dl, f):
    for _ in range(n):
        kern.spring_forces(pos, si, sj, L0, K1, K2, kMg, dec, s, dl, False, f)


@njit(cache=True)
def _loop_passes(n, pos, si, sj, L0, K1, K2, kMg, dec, s, dl, f, w):
    for _ in range(n):
        kern.spring_forces_passes(pos, si, sj, L0, K1, K2, kMg, dec, s, dl, False, f, w)


def kernel() -> None:
    for task in TASKS[:2]:
        env = gym.make(task)
        env.reset(seed=0)
        for _ in range(40):
            env.step(env.action_space.sample())
        sim = env.unwrapped.sim
        st = [np.array(a) for a in sim.tissue().symplectic_kernel_state(sim.dt)]
        pos, si, sj, L0, K1, K2, kMg, dec, s, dl = (st[0], st[6], st[7], st[8], st[9], st[10], st[13], st[14],
                                                    st[15], st[16])
        E, n = len(si), 1000
        w = np.empty((4, E))
        f1, f2 = np.zeros_like(pos), np.zeros_like(pos)
        a = _cpu(lambda: _loop_single(n, pos, si, sj, L0, K1, K2, kMg, dec, s, dl, f1)) / n
        b = _cpu(lambda: _loop_passes(n, pos, si, sj, L0, K1, K2, kMg, dec, s, dl, f2, w)) / n
        print(f"{task}: {E} springs: single pass {a / 1e3:.2f} us ({a / E:.2f} ns/spring), three passes "
              f"{b / 1e3:.2f} us ({b / E:.2f} ns/spring): x{a / b:.2f}; max |difference| / max |f| "
              f"{np.abs(f1 - f2).max() / np.abs(f1).max():.1e}")
        env.close()


def cpu_step(n: int = 300) -> None:
    out = {}
    for task in TASKS:
        env = gym.make(task)
        rng = np.random.default_rng(0)
        env.reset(seed=0)
        for a in _actions(env, 20, rng):
            env.step(a)
        res = []
        for r in range(3):
            acts = _actions(env, n, rng)
            env.reset(seed=r)
            t = time.thread_time_ns()
            for a in acts:
                _, _, term, trunc, _ = env.step(a)
                if term or trunc:
                    env.reset()
            res.append((time.thread_time_ns() - t) / n / 1e3)
        out[task] = float(np.median(res))
        env.close()
    print(json.dumps(out))


def env_python(n: int = 3000) -> None:
    for task in TASKS:
        env = gym.make(task)
        env.reset(seed=0)
        for _ in range(20):
            env.step(env.action_space.sample())
        sim = env.unwrapped.sim
        sim._physics_steps = lambda *a, **k: None     # the env's own Python only
        acts = _actions(env, n, np.random.default_rng(0))
        res = []
        for rep in range(5):
            env.unwrapped.steps = 1
            t = time.thread_time_ns()
            for a in acts[: n // 5]:
                sim.steps += 1                         # a new physics state: readings are re-read
                env.step(a)
            res.append((time.thread_time_ns() - t) / (n // 5) / 1e3)
        print(f"{task}: env Python per step {np.median(res):.1f} us (CPU, gym.make wrappers, physics stubbed)")
        env.close()


def trajectory(path: str, steps: int = 150) -> None:
    out = {}
    for task in TASKS:
        env = gym.make(task)
        rng = np.random.default_rng(1)
        rec = [env.reset(seed=3)]
        for i in range(steps):
            a = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
            if "Palpation" in task and i < 100:
                a[3] = -1.0
            r = env.step(a)
            rec.append(r)
            if r[2] or r[3]:
                rec.append(env.reset(seed=i))
        rec.append(env.unwrapped.sim.tissue().positions.copy())
        out[task] = rec
        env.close()
    with open(path, "wb") as fh:
        pickle.dump(out, fh)


def _same(x, y, path: str) -> bool:
    if isinstance(x, dict):
        return set(x) == set(y) and all(_same(x[k], y[k], f"{path}.{k}") for k in x)
    if isinstance(x, (list, tuple)):
        return len(x) == len(y) and all(_same(u, v, f"{path}[{i}]") for i, (u, v) in enumerate(zip(x, y)))
    if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
        ok = np.asarray(x).dtype == np.asarray(y).dtype and np.array_equal(x, y)
    else:
        ok = type(x) is type(y) and (x == y or (x != x and y != y))
    if not ok:
        print(f"  first difference at {path}: {x!r} vs {y!r}")
    return ok


def compare(a_path: str, b_path: str) -> None:
    with open(a_path, "rb") as fa, open(b_path, "rb") as fb:
        a, b = pickle.load(fa), pickle.load(fb)
    for task in a:
        print(task, "bit for bit identical" if _same(a[task], b[task], task) else "DIFFERENT")


def main() -> None:
    cmd, args = (sys.argv[1] if len(sys.argv) > 1 else ""), sys.argv[2:]
    if cmd == "kernel":
        kernel()
    elif cmd == "cpu-step":
        cpu_step(int(args[0]) if args else 300)
    elif cmd == "env-python":
        env_python()
    elif cmd == "trajectory" and len(args) == 1:
        trajectory(args[0])
    elif cmd == "compare" and len(args) == 2:
        compare(*args)
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main()
