"""``surgsim bench layers``: the layered model (Lin et al. 2008) at haptic rate on a large abdominal wall.

A >= 50,000-node abdominal wall (dd = 2 mm, 12 x 12 cm); a position-controlled 5 mm sphere is
pressed ``depth`` into it (all-node static solve), then moved along x at ``speed`` m/s in 1 ms
steps. Each step moves the probe (``probe.move_to``: the covered nodes held on the sphere), calls
``model.step`` (``--solver prefactored``: the contact region only, the rest recovered lazily;
``local``: the work-list local iteration with a budget of ``max_updates`` node updates) and reads
the probe force. Per step: wall time of ``model.step`` (median, p90; its thread CPU time too, which
excludes the time the scheduler gives to other processes), of the whole cycle (move + step +
force), nodes written, contact nodes, and at ``samples`` steps the probe force against the
all-node solution at the same pose (a deep copy solved by ``static_solve``). Timings depend on
the machine's load, reported with them.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import sys
import time

import numpy as np


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--spacing", type=float, default=0.002, help="lattice spacing dd, m (default 0.002: ~60k nodes)")
    p.add_argument("--steps", type=int, default=300, help="1 ms steps of probe motion (default 300)")
    p.add_argument("--depth", type=float, default=0.004, help="press depth, m")
    p.add_argument("--speed", type=float, default=0.01, help="probe speed along x, m/s")
    p.add_argument("--max-updates", type=int, default=20000, help="node updates per step (budget)")
    p.add_argument("--solver", choices=("prefactored", "local"), default="prefactored",
                   help="per-step solver: prefactored (all-node springs factorised once, contact by reactions), "
                        "or local (the work-list local iteration)")
    p.add_argument("--block-radius", type=float, default=0.002,
                   help="width (m) of the ring of lattice columns around the contact written each step (prefactored)")
    p.add_argument("--prefetch-rows", action="store_true",
                   help="prefactored: back-solve the rows of the surface around the contact in a background thread")
    p.add_argument("--stiffness", choices=("paper", "elastic"), default="paper",
                   help="node stiffness: paper (eq. 2.8 scalar springs, default) or elastic (the snapped cells' "
                        "elasticity, written whole each step)")
    p.add_argument("--samples", type=int, default=3, help="steps compared with the all-node solution")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--out", default=None, help="also write the JSON here")


def run_bench(spacing=0.002, steps=300, depth=0.004, speed=0.01, max_updates=20000, samples=3,
              progress=True, solver="prefactored", block_radius=0.002, prefetch_rows=False, stiffness="paper") -> dict:
    from tqdm import tqdm

    from surgsim_envs.contact.kinematic_probe import KinematicProbe
    from surgsim_envs.geometry.anatomy import abdominal_wall_volume
    from surgsim_envs.tissue.layered import LayeredModel

    t0 = time.perf_counter()
    vol = abdominal_wall_volume(spacing, size=(0.12, 0.12))
    bottom = vol.face_nodes(4)  # no node below: the whole bottom face
    model = LayeredModel(vol, fixed=bottom, max_updates=int(max_updates), solver=solver, block_radius=block_radius,
                         prefetch_rows=prefetch_rows, stiffness=stiffness)
    build_s = time.perf_counter() - t0
    top = np.flatnonzero(vol.neighbours[:, 5] < 0)
    z_top = float(vol.nodes[top, 2].max())
    radius, x0 = 0.005, -0.02
    probe = KinematicProbe(model, top, radius)
    probe.move_to((x0, 0.0, z_top + radius - depth))
    t = time.perf_counter()
    model.static_solve()
    static_s = time.perf_counter() - t
    sample_at = set(np.linspace(steps // samples, steps - 1, samples).astype(int).tolist()) if samples else set()
    t = time.perf_counter()
    model.step(1e-3)   # the first step factorises (prefactored solver) and compiles
    first_step_s = time.perf_counter() - t
    times, cpu, cycles, active, contacts, forces, cmp = [], [], [], [], [], [], []
    for k in tqdm(range(steps), desc="bench layers", unit="step", file=sys.stderr, disable=not progress):
        t0 = time.perf_counter()
        probe.move_to((x0 + speed * 1e-3 * (k + 1), 0.0, z_top + radius - depth))
        t = time.perf_counter()
        c = time.thread_time()
        model.step(1e-3)
        cpu.append(time.thread_time() - c)
        t1 = time.perf_counter()
        forces.append(float(probe.force()[2]))
        t2 = time.perf_counter()
        times.append(t1 - t)
        cycles.append(t2 - t0)
        active.append(model.last_active)
        contacts.append(len(probe.nodes))
        if k in sample_at:
            ref = copy.deepcopy(model)
            ref.static_solve()
            f_ref = float(ref.contact_force(probe.nodes)[2])
            cmp.append({"step": k, "force": forces[-1], "all_node_force": f_ref,
                        "error": abs(forces[-1] / f_ref - 1.0), "left_over": int(model.unconverged)})
    return {"bench": "layers", "nodes": int(vol.n_nodes), "surface_triangles": int(len(vol.surface)),
            "spacing_m": spacing, "depth_m": depth, "speed_m_s": speed, "steps": steps,
            "max_updates": int(max_updates), "solver": solver, "stiffness": stiffness, "first_step_s": first_step_s, "block_radius_m": block_radius, "prefetch_rows": prefetch_rows,
            "build_s": build_s, "static_solve_s": static_s,
            "ms_per_step_median": 1e3 * float(np.median(times)), "ms_per_step_p90": 1e3 * float(np.percentile(times, 90)),
            "cpu_ms_per_step_median": 1e3 * float(np.median(cpu)),
            "cpu_ms_per_step_p90": 1e3 * float(np.percentile(cpu, 90)),
            "ms_per_cycle_median": 1e3 * float(np.median(cycles)),
            "ms_per_cycle_p90": 1e3 * float(np.percentile(cycles, 90)),
            "ms_per_cycle_max": 1e3 * float(np.max(cycles)),
            "active_nodes_median": float(np.median(active)), "contact_nodes_median": float(np.median(contacts)),
            "fallbacks": int(getattr(model, "prefactored_fallbacks", 0)), "ms_per_step_max": 1e3 * float(np.max(times)), "force_N_median": float(np.median(forces)),
            "force_vs_all_node": cmp, "max_force_error": max((c["error"] for c in cmp), default=float("nan")),
            "load": os.getloadavg(), "cpus": os.cpu_count()}


#: 1 ms probe steps one run may take (the default 300 is a 0.3 s sweep; 10^6 is a quarter hour of probing)
MAX_PROBE_STEPS = 1_000_000


def run(args) -> int:
    from surgsim_envs import validate

    validate.integer(args.steps, "--steps", lo=1, hi=MAX_PROBE_STEPS,
                     fix=f"1 ms steps of probe motion, at most {MAX_PROBE_STEPS:,}")
    validate.integer(args.samples, "--samples", lo=0, hi=args.steps, fix="steps compared with the all-node solution")
    validate.real(args.spacing, "--spacing", lo=1e-3, hi=0.02, unit="m",
                  fix="a lattice spacing in [0.001, 0.02] m, e.g. 0.002 (finer is millions of nodes)")
    validate.real(args.depth, "--depth", lo=0.0, hi=0.015, lo_open=True, unit="m",
                  fix="a press depth in (0, 0.015] m (the wall is 29 mm thick), e.g. 0.004")
    validate.real(args.speed, "--speed", lo=0.0, hi=1.0, unit="m/s", fix="a probe speed in [0, 1] m/s, e.g. 0.01")
    validate.real(args.block_radius, "--block-radius", lo=0.0, hi=0.06, unit="m",
                  fix="a block radius in [0, 0.06] m (the patch is 12 cm wide), e.g. 0.002")
    validate.integer(args.max_updates, "--max-updates", lo=1, hi=10_000_000, fix="node updates per step, e.g. 20000")
    if args.out:
        validate.writable_file(args.out, "--out")
    res = run_bench(args.spacing, args.steps, args.depth, args.speed, args.max_updates, args.samples,
                    solver=args.solver, block_radius=args.block_radius, prefetch_rows=args.prefetch_rows,
                    stiffness=args.stiffness)
    text = json.dumps(res, indent=2)
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(text)
    if args.json:
        print(text)
    else:
        print(f"layered: {res['nodes']:,} nodes, {res['ms_per_step_median']:.3f} ms/step (median; "
              f"{res['ms_per_cycle_median']:.3f} ms with the probe's move and force), "
              f"{res['active_nodes_median']:.0f} active nodes, force error vs all-node <= {res['max_force_error']:.1%} "
              f"(load {res['load'][0]:.1f} on {res['cpus']} cpus)")
    return 0
