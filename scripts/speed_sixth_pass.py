"""Measurements behind docs/benchmarks.md, "Env step: sixth pass (issue 18)". Thread CPU time; run
with ``MUJOCO_GL=egl`` and ``PYTHONPATH`` set to this tree; BASE is an unpacked tree of the commit to
compare with (e.g. ``git archive f8e5825 | tar -x -C /tmp/base``), whose kernel modules are loaded
under other names into the same process and timed round robin with this tree's:

    python scripts/speed_sixth_pass.py springs BASE    # spring_forces_passes, Palpation / Grasp lattices
    python scripts/speed_sixth_pass.py contact BASE    # contact_kernel_prepared, tools 1 m away / pressing
    python scripts/speed_sixth_pass.py env-cpu         # CPU us per env.step of the tree on PYTHONPATH

``env-cpu`` (9 blocks of 300 random steps per task, resets excluded: median and min) is to be run
alternately with ``PYTHONPATH`` on each tree. Each kernel mode also reports whether the two trees'
outputs are equal (``==``).
"""

from __future__ import annotations

import importlib.util
import json
import sys
import time

import gymnasium as gym
import numpy as np
from numba import njit

import surgsim_envs
from surgsim_envs.contact import model as contact_model
from surgsim_envs.tissue import msd_kernels

TASKS = ("SurgSim/Palpation-v0", "SurgSim/Grasp-v0")


def _load(base: str, rel: str, name: str):
    spec = importlib.util.spec_from_file_location(name, f"{base}/surgsim_envs/{rel}")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod         # dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


def _env(task: str, pressing: bool):
    env = gym.make(task)
    env.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(20):
        a = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
        if pressing and "Palpation" in task:
            a[2], a[3] = 0.4, -1.0
        elif pressing:
            a[3] = 1.0
        env.step(a)
    return env


def _copy(state):
    return tuple(np.array(x, copy=True) if isinstance(x, np.ndarray) else x for x in state)


def springs(base: str, n: int = 3000, rounds: int = 25) -> dict:
    old = _load(base, "tissue/msd_kernels.py", "_msd_base")

    def make(kern):
        @njit(cache=False)
        def loop(n, pos, si, sj, L0, K1, K2, kMg, dec, s, dl, f, w):
            for _ in range(n):
                kern.spring_forces_passes(pos, si, sj, L0, K1, K2, kMg, dec, s, dl, False, f, w)
        return loop

    loops = {"base": make(old), "this": make(msd_kernels)}
    out = {}
    for task in TASKS:
        env = _env(task, False)
        sim = env.unwrapped.sim
        t = sim.tissue()
        ks = list(_copy(t.symplectic_kernel_state(sim.dt)))
        si, sj, L0, K1, K2, kMg, decay, s, dl, f_buf = ks[6:11] + ks[13:18]
        pos, w = t.positions.copy(), np.empty((4, len(si)))
        fs = {}
        for k, lp in loops.items():
            fs[k] = np.zeros_like(f_buf)
            lp(1, pos, si, sj, L0, K1, K2, kMg, decay, s, dl, fs[k], w)
        times = {k: [] for k in loops}
        for _ in range(rounds):
            for k, lp in loops.items():
                t0 = time.thread_time_ns()
                lp(n, pos, si, sj, L0, K1, K2, kMg, decay, s, dl, f_buf, w)
                times[k].append((time.thread_time_ns() - t0) / n / 1e3)
        out[task] = {"springs": len(si), "same_forces": bool(np.array_equal(fs["base"], fs["this"])),
                     **{f"{k}_us": round(float(np.median(v)), 2) for k, v in times.items()}}
        env.close()
    return out


def contact(base: str, n: int = 3000, rounds: int = 21) -> dict:
    old = _load(base, "contact/model.py", "_contact_base")

    def make(fn):
        @njit(cache=False)
        def loop(n, pos, vel, gpos, gmat, gvel, tcom, st):
            for _ in range(n):
                fn(pos, vel, gpos, gmat, gvel, tcom, st)
        return loop

    loops = {"base": make(old.contact_kernel_prepared), "this": make(contact_model.contact_kernel_prepared)}
    out = {}
    for task in TASKS:
        env = _env(task, True)
        sim = env.unwrapped.sim
        cm = next(iter(sim.contacts.values()))
        ks = cm.kernel_state()
        nbase = len(ks) if hasattr(old, "_row_lists") else 36    # before this pass: no ``rows`` entry
        ga = sim._gather_args
        gpos, gmat, gvel, tcom = (np.array(ga[i]) for i in (9, 10, 11, 12))
        pos, vel = sim.tissue().positions.copy(), sim.tissue().velocities.copy()
        res = {"points": int(cm.n_points), "geoms": int(len(ks[4]))}
        for case, gp in (("far", gpos + np.array([0.0, 0.0, 1.0])), ("pressing", gpos)):
            sts = {"base": _copy(ks[:nbase]), "this": _copy(ks)}
            for k, lp in loops.items():
                lp(3, pos, vel, gp, gmat, gvel, tcom, sts[k])
            same = all(np.array_equal(a, b) for a, b in zip(sts["base"][:31], sts["this"][:31])
                       if isinstance(a, np.ndarray))        # [31] the positions copy: rows written only
            times = {k: [] for k in loops}
            for _ in range(rounds):
                for k, lp in loops.items():
                    t0 = time.thread_time_ns()
                    lp(n, pos, vel, gp, gmat, gvel, tcom, sts[k])
                    times[k].append((time.thread_time_ns() - t0) / n / 1e3)
            res[case] = {"same_outputs": bool(same),
                         "points_in_contact": int(np.count_nonzero(sts["this"][12].any(axis=1))),
                         **{f"{k}_us": round(float(np.median(v)), 2) for k, v in times.items()}}
        out[task] = res
        env.close()
    return out


def env_cpu(steps: int = 300, blocks: int = 9) -> dict:
    out = {}
    for task in TASKS:
        env = gym.make(task)
        env.reset(seed=0)
        acts = np.random.default_rng(0).uniform(-1, 1, (steps, *env.action_space.shape)).astype(np.float32)
        if "Palpation" in task:
            acts[:, 3] = -1.0
        for a in acts[:30]:
            env.step(a)
        res = []
        for b in range(blocks):
            env.reset(seed=b)
            total = 0
            for a in acts:
                t0 = time.thread_time_ns()
                r = env.step(a)
                total += time.thread_time_ns() - t0
                if r[2] or r[3]:
                    env.reset()
            res.append(total / steps / 1e3)
        out[task] = {"median_us": round(float(np.median(res)), 1), "min_us": round(min(res), 1)}
        env.close()
    return out


def main() -> None:
    cmd, args = (sys.argv[1] if len(sys.argv) > 1 else ""), sys.argv[2:]
    if cmd == "springs" and len(args) == 1:
        res = springs(args[0])
    elif cmd == "contact" and len(args) == 1:
        res = contact(args[0])
    elif cmd == "env-cpu":
        res = env_cpu()
    else:
        sys.exit(__doc__)
    res["tree"] = surgsim_envs.__file__
    res["load"] = open("/proc/loadavg").read().split()[:3]
    print(json.dumps(res))


if __name__ == "__main__":
    main()
