"""Same-process step timings of the fractional model (docs/benchmarks.md, docs/models/fractional.md).

    PYTHONPATH=. python scripts/fractional_speed.py [--nodes 1000] [--repeats 9] [--steps 100]

(from the repository root: without PYTHONPATH=. the script imports whichever surgsim_envs is
installed, not this tree's)

Two tables, medians over repeats of wall-clock and stepping-thread CPU time per step, with the
load average (the machine is shared: prefer the CPU column and the ratios):
1. fractional (default memory) against fem (corotational) and mass_spring, all symplectic at half their
   own critical dt, the 1,000-node liver block of ``surgsim bench speed`` (bottom clamped, 0.5 N);
2. fractional memories after the rings are full: the default (L = 100 + 198 block averages of 50
   steps, spanning 10,000 steps), plain truncation at L = 100 (the default before the two-level
   memory was), L = 100 + 33 blocks of 100 and L = 3,400 (a span kept in full); with the ratio
   of each to plain L = 100.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from surgsim_envs.bench.speed_volume import bench_volume
from surgsim_envs.tissue import registry
from surgsim_envs.tissue.fractional import FractionalTetModel


def _time(models: dict, dts: dict, forces, repeats: int, steps: int) -> dict:
    res = {k: ([], []) for k in models}
    for _ in range(repeats):
        for k, m in models.items():          # interleaved: every case sees the same load
            t0, c0 = time.perf_counter(), time.thread_time()
            for _ in range(steps):
                m.step(dts[k], forces)
            res[k][0].append((time.perf_counter() - t0) / steps * 1e6)
            res[k][1].append((time.thread_time() - c0) / steps * 1e6)
    return {k: (statistics.median(w), statistics.median(c)) for k, (w, c) in res.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--nodes", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--steps", type=int, default=100)
    args = parser.parse_args()
    vol = bench_volume(args.nodes)
    z = vol.nodes[:, 2]
    bottom, top = np.isclose(z, z.min()), np.isclose(z, z.max())
    forces = np.zeros((vol.n_nodes, 3))
    forces[top, 2] = -0.5 / top.sum()

    models = {"fractional default": FractionalTetModel(vol, "liver", integrator="symplectic", fixed=bottom),
              "fem": registry.get("fem")(vol, "liver", integrator="symplectic", fixed=bottom),
              "mass_spring": registry.get("mass_spring")(vol, "liver", integrator="symplectic", fixed=bottom)}
    dts = {k: min(1e-3, 0.5 * m.critical_dt()) for k, m in models.items()}
    for k, m in models.items():
        for _ in range(150):
            m.step(dts[k], forces)
    out = _time(models, dts, forces, args.repeats, args.steps)
    print(f"{vol.n_nodes} nodes, symplectic, load {os.getloadavg()[0]:.1f}")
    for k, (w, c) in out.items():
        print(f"  {k:<22} wall {w:8.1f} us   cpu {c:8.1f} us   dt {dts[k] * 1e3:.3f} ms")

    cases = {"L=100": dict(memory=100, coarse_blocks=0), "default (100 + 198x50)": {},
             "L=100 + 33x100": dict(memory=100, coarse_blocks=33, coarse_step=100), "L=3400": dict(memory=3400, coarse_blocks=0)}
    models = {k: FractionalTetModel(vol, "liver", integrator="symplectic", fixed=bottom, **kw) for k, kw in cases.items()}
    dt = 0.5 * models["L=100"].critical_dt()
    dts = {k: dt for k in models}
    for k, m in models.items():
        for _ in range(10100 if k.startswith("default") else 3500 if k != "L=100" else 150):   # fill the rings
            m.step(dt, forces)
    out = _time(models, dts, forces, max(3, args.repeats // 2), max(20, args.steps // 2))
    print(f"fractional memory, {vol.n_nodes} nodes, symplectic, load {os.getloadavg()[0]:.1f}")
    for k, (w, c) in out.items():
        print(f"  {k:<22} wall {w:8.1f} us   cpu {c:8.1f} us   cpu / plain L=100 {c / out['L=100'][1]:.2f}")


if __name__ == "__main__":
    main()
