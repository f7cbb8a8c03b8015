"""``surgsim bench diffusion``: time per update of the diffusion model, next to the paper's Table 9.1.

For each point count of Table 9.1 (261, 405, 650, 900, 1,100; the cube grid gives the nearest
6n^2 - 12n + 8) the isotropic figure case (omega 0.08, 3 kg press, eq. 9.9 grid scheme) takes
``--steps`` updates per repeat; the median over ``--repeats`` is reported both in wall-clock time
and in process CPU time (the machine may be shared: CPU time is what the update costs, wall time
what a caller waited), with the load average. Two rows per size: one paper-style update
(``substeps=1`` at 0.9 x the stability bound) and the cost of one simulated millisecond (dt 1 ms,
``substeps="auto"``), which is what a 1 kHz haptic loop pays.

The paper's numbers: an Intel Pentium 2.8 GHz, "graphical update" time per frame (ms).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import numpy as np

from surgsim_envs.errors import ConfigError

#: Table 9.1 of Zhong et al. 2016: points -> computational time (ms) on a Pentium 2.8 GHz
PAPER_TABLE = {261: 4.3, 405: 8.5, 650: 12.4, 900: 24.3, 1100: 39.8}
#: speed target (haptic rate): a 1,100-point surface at most this many microseconds per update
TARGET_US = 200.0


def _cpu_name() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def time_updates(model, forces, dt: float, steps: int, repeats: int) -> tuple[float, float]:
    """Median (wall, cpu) seconds per ``model.step(dt, forces)`` over ``repeats`` runs of ``steps``."""
    model.step(dt, forces)                  # compile / warm up
    wall, cpu = [], []
    for _ in range(repeats):
        model.reset()
        t, c = time.perf_counter(), time.process_time()
        for _ in range(steps):
            model.step(dt, forces)
        wall.append((time.perf_counter() - t) / steps)
        cpu.append((time.process_time() - c) / steps)
    return float(np.median(wall)), float(np.median(cpu))


def run_bench(steps: int = 1000, repeats: int = 5, sizes=tuple(PAPER_TABLE)) -> dict:
    from surgsim_envs.bench.diffusion_press import contact_forces, paper_case

    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover
        def tqdm(x, **_):
            return x
    if steps < 1 or repeats < 1:
        raise ConfigError(f"--steps and --repeats must be >= 1, got {steps}, {repeats}")
    rows = []
    load_before = os.getloadavg()
    for pts in tqdm(sizes, desc="bench diffusion"):
        paper = paper_case("isotropic", points=int(pts), substeps=1)
        f = contact_forces(paper)
        dt1 = 0.9 * paper.critical_dt()
        w1, c1 = time_updates(paper, f, dt1, steps, repeats)
        auto = paper_case("isotropic", points=int(pts))
        w2, c2 = time_updates(auto, f, 1e-3, max(1, steps // 2), repeats)
        rows.append({"paper_points": int(pts), "nodes": int(paper.n_nodes), "paper_ms": PAPER_TABLE.get(int(pts)),
                     "update_wall_us": w1 * 1e6, "update_cpu_us": c1 * 1e6, "stable_dt_ms": dt1 * 1e3,
                     "per_ms_wall_us": w2 * 1e6, "per_ms_cpu_us": c2 * 1e6, "substeps_at_1ms": int(auto.substeps)})
    return {"bench": "diffusion", "cpu": _cpu_name(), "cores": os.cpu_count(), "load_before": load_before,
            "load_after": os.getloadavg(), "steps": steps, "repeats": repeats, "target_us_1100": TARGET_US,
            "rows": rows}


def markdown(result: dict) -> str:
    out = ["| points (paper) | nodes (ours) | paper ms/update | ours us/update wall | ours us/update CPU | "
           "speed-up (CPU) | us per simulated ms (CPU, substeps) |", "|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        su = r["paper_ms"] * 1e3 / r["update_cpu_us"] if r["paper_ms"] else float("nan")
        out.append(f"| {r['paper_points']} | {r['nodes']} | {r['paper_ms']} | {r['update_wall_us']:.0f} | "
                   f"{r['update_cpu_us']:.0f} | {su:.0f}x | {r['per_ms_cpu_us']:.0f} ({r['substeps_at_1ms']}) |")
    la, lb = result["load_before"], result["load_after"]
    out.append(f"\n{result['cpu']}, {result['cores']} cores; load average before {la[0]:.2f}, after {lb[0]:.2f}; "
               f"medians of {result['repeats']} x {result['steps']} updates.")
    return "\n".join(out)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--steps", type=int, default=1000, help="updates per repeat (default 1000)")
    parser.add_argument("--repeats", type=int, default=5, help="repeats; the median is reported (default 5)")
    parser.add_argument("--sizes", type=int, nargs="+", default=list(PAPER_TABLE), help="point counts")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a markdown table")


def run(args) -> int:
    result = run_bench(args.steps, args.repeats, tuple(args.sizes))
    print(json.dumps(result, indent=2) if args.json else markdown(result))
    return 0
