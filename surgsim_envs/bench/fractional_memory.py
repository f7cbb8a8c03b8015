"""``surgsim bench memory``: the short-memory principle of the fractional model, error and cost against L.

* error: a liver block (bottom clamped) under a constant top load for ``--duration`` s, stepped
  implicitly at dt; the top-face displacement history with memory L is compared with the run
  that keeps the whole history (L = number of steps). Reported: max over time of the difference
  / max displacement of the full run (creep curves in the figure).
* cost: median microseconds per symplectic step of the ``--nodes`` block (5 mm lattice, liver,
  0.5 N on the top, dt = half the critical dt) for each L, medians over ``--repeats`` repeats.

Optional ``--plot FILE`` draws both against L. Timings depend on machine load: run with the
load average stated next to them.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

from surgsim_envs.errors import ConfigError

DEFAULT_MEMORIES = (5, 10, 20, 50, 100, 200, 500, 1000)


def _block(target: int):
    from surgsim_envs.bench.speed_volume import bench_volume

    vol = bench_volume(target)
    z = vol.nodes[:, 2]
    return vol, np.isclose(z, z.min()), np.isclose(z, z.max())


def creep_error(memories, *, nodes: int = 250, duration: float = 2.0, dt: float = 1e-3, order: float = 0.4,
                material="liver", progress: bool = True) -> dict:
    """{"time", "full": (S,) top displacement (m) with the whole history, "curves": {L: (S,)},
    "error": {L: max |u_L - u_full| / max |u_full|}}."""
    from tqdm import tqdm

    from surgsim_envs.tissue.fractional import FractionalTetModel

    vol, bottom, top = _block(nodes)
    steps = int(round(duration / dt))
    if steps < 2:
        raise ConfigError(f"duration / dt must give >= 2 steps, got duration={duration}, dt={dt}")

    def run(mem):
        m = FractionalTetModel(vol, material, order=order, memory=mem, coarse_blocks=0, integrator="implicit",
                              fixed=bottom)
        forces = np.zeros((m.n_nodes, 3))
        forces[top, 2] = -0.5 / top.sum()
        out = np.empty(steps)
        z0 = vol.nodes[top, 2].mean()
        for k in range(steps):
            m.step(dt, forces)
            out[k] = z0 - m.positions[top, 2].mean()
        return out

    full = run(steps)
    curves, errors = {}, {}
    for mem in tqdm(list(memories), desc="memory error", file=sys.stderr, disable=not progress):
        curves[int(mem)] = run(int(mem))
        errors[int(mem)] = float(np.max(np.abs(curves[int(mem)] - full)) / np.max(np.abs(full)))
    return {"time": dt * np.arange(1, steps + 1), "full": full, "curves": curves, "error": errors,
            "nodes": int(vol.n_nodes), "dt": dt, "order": order}


def step_cost(memories, *, nodes: int = 1000, repeats: int = 7, steps: int = 100, warmup: int = 20,
              integrator: str = "symplectic", progress: bool = True) -> dict:
    """{"us_per_step": {L: median wall-clock us per step}, "cpu_us_per_step": {L: median CPU time of
    the stepping thread, us}} of the ``nodes`` block stepped with ``integrator`` (the CPU time
    excludes the time the thread waited for a core on a loaded machine)."""
    from tqdm import tqdm

    from surgsim_envs.tissue.fractional import FractionalTetModel

    vol, bottom, top = _block(nodes)
    out, cpu_out = {}, {}
    for mem in tqdm(list(memories), desc="memory cost", file=sys.stderr, disable=not progress):
        m = FractionalTetModel(vol, "liver", memory=int(mem), coarse_blocks=0, integrator=integrator, fixed=bottom)
        dt = 1e-3 if integrator == "implicit" else min(1e-3, 0.5 * m.critical_dt())
        forces = np.zeros((m.n_nodes, 3))
        forces[top, 2] = -0.5 / top.sum()
        for _ in range(warmup + int(mem)):          # fill the history: a full ring is the steady cost
            m.step(dt, forces)
        times, cpu = [], []
        for _ in range(repeats):
            t0, c0 = time.perf_counter(), time.thread_time()
            for _ in range(steps):
                m.step(dt, forces)
            times.append((time.perf_counter() - t0) / steps * 1e6)
            cpu.append((time.thread_time() - c0) / steps * 1e6)
        out[int(mem)] = round(statistics.median(times), 1)
        cpu_out[int(mem)] = round(statistics.median(cpu), 1)
    return {"us_per_step": out, "cpu_us_per_step": cpu_out, "nodes": int(vol.n_nodes), "integrator": integrator}


def plot(err: dict, cost: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b, c) = plt.subplots(1, 3, figsize=(12, 3.6))
    a.plot(err["time"], err["full"] * 1e3, "k-", lw=2, label="full history")
    for mem, curve in err["curves"].items():
        a.plot(err["time"], curve * 1e3, lw=0.9, label=f"L = {mem}")
    a.set_xlabel("time (s)")
    a.set_ylabel("top displacement (mm)")
    a.set_title(f"creep under 0.5 N, q = {err['order']}, dt = {err['dt'] * 1e3:g} ms", fontsize=9)
    a.legend(fontsize=6)
    mems = sorted(err["error"])
    b.loglog(mems, [max(err["error"][m], 1e-16) for m in mems], "o-")
    b.set_xlabel("short memory L (steps)")
    b.set_ylabel("max |u_L - u_full| / max u_full")
    b.set_title(f"error, {err['nodes']} nodes", fontsize=9)
    b.grid(True, which="both", alpha=0.3)
    cm = sorted(cost["us_per_step"])
    c.plot(cm, [cost["us_per_step"][m] for m in cm], "s-", label="wall clock")
    c.plot(cm, [cost["cpu_us_per_step"][m] for m in cm], "o--", label="thread CPU time")
    c.legend(fontsize=7)
    c.set_xscale("log")
    c.set_xlabel("short memory L (steps)")
    c.set_ylabel("us per step (median)")
    load = os.getloadavg()[0]
    c.set_title(f"cost, {cost['nodes']} nodes, {cost['integrator']}, load {load:.1f}", fontsize=9)
    c.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _memories(text: str) -> list[int]:
    try:
        vals = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise ConfigError(f"--memories must be comma-separated integers like 10,100,1000, got {text!r}") from None
    if not vals or min(vals) < 1:
        raise ConfigError(f"--memories needs integers >= 1, got {text!r}")
    return vals


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--memories", default=",".join(map(str, DEFAULT_MEMORIES)), help="short-memory lengths L")
    parser.add_argument("--nodes", type=int, default=1000, help="node count of the cost block (default 1000)")
    parser.add_argument("--error-nodes", type=int, default=250, help="node count of the error block (default 250)")
    parser.add_argument("--duration", type=float, default=2.0, help="creep duration s for the error (default 2)")
    parser.add_argument("--repeats", type=int, default=7, help="timed repeats per L (median reported)")
    parser.add_argument("--integrator", default="symplectic", choices=["symplectic", "implicit"])
    parser.add_argument("--plot", default=None, help="write the chart here (PNG)")
    parser.add_argument("--json", action="store_true")


def run(args: argparse.Namespace) -> int:
    from surgsim_envs import validate

    mems = _memories(args.memories)
    validate.integer(args.nodes, "--nodes", lo=8, hi=1_000_000, fix="the cost block's node count, e.g. 1000")
    validate.integer(args.error_nodes, "--error-nodes", lo=8, hi=100_000, fix="the error block's node count, e.g. 250")
    validate.duration(args.duration, "--duration", hi=600.0, fix="a creep duration in (0, 600] s, e.g. 2")
    validate.integer(args.repeats, "--repeats", lo=1, hi=100, fix="timed repeats per L, e.g. 7")
    err = creep_error(mems, nodes=args.error_nodes, duration=args.duration)
    cost = step_cost(mems, nodes=args.nodes, repeats=args.repeats, integrator=args.integrator)
    load = os.getloadavg()
    if args.plot:
        plot(err, cost, args.plot)
    rows = [{"memory": m, "error": err["error"][m], "us_per_step": cost["us_per_step"][m],
             "cpu_us_per_step": cost["cpu_us_per_step"][m]} for m in mems]
    if args.json:
        print(json.dumps({"rows": rows, "error_nodes": err["nodes"], "cost_nodes": cost["nodes"],
                          "integrator": cost["integrator"], "load_average": load}, indent=2))
    else:
        print(f"{'L':>6} {'rel. error':>12} {'us/step':>10} {'cpu us':>8}   (error: {err['nodes']} nodes implicit; "
              f"cost: {cost['nodes']} nodes {cost['integrator']}; load {load[0]:.2f})")
        for r in rows:
            print(f"{r['memory']:>6} {r['error']:>12.3e} {r['us_per_step']:>10.1f} {r['cpu_us_per_step']:>8.1f}")
    return 0
