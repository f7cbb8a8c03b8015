"""``surgsim bench growth``: time of the tissue-growth iteration (Vandewalle et al. 2003) on a ~10,000-node mesh.

The synthetic maxillofacial case (:mod:`surgsim_envs.planning.maxillofacial`) meshed to about
``--nodes`` nodes; per repeat a fresh :class:`~surgsim_envs.tissue.growth.GrowthSolver` (the
model, its stiffness and element operators are built once, outside the timings):

* ``factor``: nested-dissection ordering + sparse LU of K (once per mesh and Dirichlet set);
* ``grow``: the full growth iteration with that factorisation: basic solve, tensile part,
  self-equilibrated growth stress, and every iteration (solve + stresses) to tol = 1e-5;
* ``per_iteration``: grow / (iterations + 2 solves).

Medians over ``--repeats`` of wall time and of process CPU time (``time.process_time``: on a
shared, overloaded machine the CPU time is what one unshared core would need; the process is
single-threaded: SuperLU and the element operators run on one core).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time


#: nodes the growth benchmark meshes at most
MAX_GROWTH_NODES = 200_000


def case_spacing(case, nodes: int) -> float:
    """Largest spacing (m) whose mesh has at least ``nodes`` nodes."""
    from surgsim_envs.geometry.box import box_volume

    spacing = 0.006
    while spacing > 1e-4:
        vol = box_volume((case.width, case.height, case.thickness), spacing=spacing)
        if vol.n_nodes >= nodes:
            return spacing
        spacing *= 0.98
    return spacing


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--nodes", type=int, default=10000, help="target node count (default 10,000)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--k", type=float, default=20.0)
    parser.add_argument("--out", default="surgsim-out/bench_growth", help="output directory (growth_speed.json)")


def check_args(args: argparse.Namespace) -> None:
    """ConfigError naming the first bad flag, before anything is meshed."""
    from surgsim_envs import validate

    validate.integer(args.nodes, "--nodes", lo=100, hi=MAX_GROWTH_NODES,
                     fix=f"the growth solve factors a sparse matrix of 3 x nodes rows; above {MAX_GROWTH_NODES:,} "
                         "nodes it takes hours and tens of GB")
    validate.integer(args.repeats, "--repeats", lo=1, hi=100, fix="e.g. 3")
    validate.positive(args.k, "--k", hi=1e6, fix="the growth constant, e.g. 20")


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from surgsim_envs.planning.maxillofacial import DistractionCase
    from surgsim_envs.tissue.growth import GrowthSolver
    from surgsim_envs.tissue.growth_ops import ElementOperators

    check_args(args)
    case = DistractionCase()
    spacing = case_spacing(case, args.nodes)
    t0 = time.perf_counter()
    model = case.model(spacing, 0.25)
    ops = ElementOperators.from_model(model)
    stiffness = ops.stiffness()
    build = time.perf_counter() - t0
    rows = []
    for _ in tqdm(range(args.repeats), desc="bench growth", unit="repeat", file=sys.stderr):
        solver = GrowthSolver(ops, stiffness, model.fixed, model.fixed_targets - model.rest_positions)
        t, c = time.perf_counter(), time.process_time()
        solver.factor()
        factor, factor_cpu = time.perf_counter() - t, time.process_time() - c
        t, c = time.perf_counter(), time.process_time()
        res = solver.grow(args.k)
        grow, grow_cpu = time.perf_counter() - t, time.process_time() - c
        rows.append({"factor_s": factor, "grow_s": grow, "factor_cpu_s": factor_cpu, "grow_cpu_s": grow_cpu,
                     "iterations": res.iterations})
    med = {key: statistics.median(r[key] for r in rows) for key in ("factor_s", "grow_s", "factor_cpu_s", "grow_cpu_s")}
    iters = rows[-1]["iterations"]
    per_it = med["grow_s"] / (iters + 2)
    out = {"nodes": model.n_nodes, "elements": int(len(model.tets)), "spacing_m": spacing, "k": args.k,
           "iterations": iters, "median_factor_s": med["factor_s"], "median_grow_s": med["grow_s"],
           "per_iteration_s": per_it, "grow_14_iterations_s": 16 * per_it, "build_s": build,
           "median_factor_cpu_s": med["factor_cpu_s"], "median_grow_cpu_s": med["grow_cpu_s"],
           "repeats": args.repeats, "load": os.getloadavg(), "rows": rows}
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "growth_speed.json"), "w") as fh:
        json.dump(out, fh, indent=1)
    print(f"{model.n_nodes} nodes, {len(model.tets)} tets (spacing {spacing * 1e3:.2f} mm), k = {args.k:g}: "
          f"{iters} iterations")
    print(f"median over {args.repeats}: factor (ordering + LU, once) {med['factor_s']:.2f} s, "
          f"growth iteration {med['grow_s']:.2f} s ({per_it * 1e3:.0f} ms per solve+stress; 14 iterations "
          f"-> {16 * per_it:.2f} s), total {med['factor_s'] + med['grow_s']:.2f} s")
    print(f"process CPU time (what one unshared core would need): factor {med['factor_cpu_s']:.2f} s, growth "
          f"iteration {med['grow_cpu_s']:.2f} s, total {med['factor_cpu_s'] + med['grow_cpu_s']:.2f} s")
    print(f"load average {os.getloadavg()[0]:.2f} (2 cores, shared); model build (not timed above) {build:.1f} s")
    return 0
