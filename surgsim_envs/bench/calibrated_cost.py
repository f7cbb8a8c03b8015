"""Cost of ``mass_spring_calibrated`` against the plain ``mass_spring`` network, same process, on the
palpation task's tissue (10 x 10 x 2 cm liver slab with a 20 kPa inclusion, 5 mm lattice, bed fixed)
and the indentation bench slab (docs/benchmarks.md "Calibrated mass-spring on the chart").

    surgsim bench calibrated-cost [--repeats 200]

Per model: springs (left out: those the fit set to 0), critical_dt() (what the "auto" integrator and stable_dt() use)
against the exact symplectic limit from the largest eigenvalue of M^-1 K (scipy eigsh), wall time
of one symplectic and one implicit step (median over ``repeats``, after numba compilation; the two
models stepped in turn so that the machine load hits both alike) and
compute per simulated ms = step time x steps per ms (symplectic at stable_dt(), implicit at 1 ms), the
symplectic step's two force passes timed alone (spring pass, nodal volume term), and
the cost of a masked ``scale_material`` (what a task's reset does to re-randomise an inclusion:
the calibrated constants are a linear map of the tets' moduli, no refit).
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np


def exact_critical_dt(model) -> float:
    """2/sqrt(lambda_max(M^-1 K)) with nodal damping: the symplectic limit of the linearised model."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    K = model.stiffness_matrix(relaxed=False).tocsr()
    free = np.repeat(~model.fixed, 3)
    mi = np.repeat(1.0 / np.sqrt(model.masses), 3)[free]
    A = sp.diags(mi) @ K[free][:, free] @ sp.diags(mi)
    lam = float(spla.eigsh(A, k=1, which="LA", return_eigenvectors=False, tol=1e-4)[0])
    beta = float(np.max(model.b0 / model.masses))
    return (-beta + math.sqrt(beta * beta + 4.0 * lam)) / lam


def interleaved_step_us(models, dt_of, repeats: int) -> list[float]:
    """Median wall time (us) of one step of each model, the models stepped in turn (one step each per
    round) so that a changing machine load hits them alike."""
    forces = []
    for m in models:
        f = np.zeros((m.n_nodes, 3))
        top = m.rest_positions[:, 2] >= m.rest_positions[:, 2].max() - 1e-9
        f[top, 2] = -0.02 / max(int(top.sum()), 1)
        forces.append(f)
        for _ in range(5):                  # compile / warm up
            m.step(dt_of(m), f)
    times = [[] for _ in models]
    for _ in range(repeats):
        for k, m in enumerate(models):
            t0 = time.perf_counter()
            m.step(dt_of(m), forces[k])
            times[k].append(time.perf_counter() - t0)
    return [float(np.median(t) * 1e6) for t in times]


def kernel_split_us(model, dt: float, repeats: int) -> tuple[float, float]:
    """Median wall time (us) of the symplectic step's two force passes at the current state: the spring pass
    (``msd_kernels.spring_forces_passes``, branches not committed) and the nodal volume term
    (``nodal_volume_kernels.add_forces``; 0 for a model without it)."""
    from surgsim_envs.tissue import msd_kernels as kern
    from surgsim_envs.tissue import nodal_volume_kernels as nvk

    state = model.symplectic_kernel_state(dt)
    (pos, si, sj, L0, K1, K2), (kMg, decay, s, dl, f_buf) = (state[0], *state[6:11]), state[13:18]
    work = model.spring_work()
    ntets = getattr(model, "volume_tets", None)      # the calibrated model's nodal volume term
    calls = [lambda: kern.spring_forces_passes(pos, si, sj, L0, K1, K2, kMg, decay, s, dl, False, f_buf, work)]
    if ntets is not None:
        fvol = np.zeros_like(pos)
        vbuf = np.zeros(model.n_nodes)          # the kernel's per-node volume scratch
        calls.append(lambda: nvk.add_forces(pos, ntets, model.node_rest_volume, model.node_bulk, vbuf, fvol))
    times = [[] for _ in calls]
    for _ in range(max(repeats, 10)):
        for k, call in enumerate(calls):
            t0 = time.perf_counter()
            call()
            times[k].append(time.perf_counter() - t0)
    us = [float(np.median(t) * 1e6) for t in times]
    return us[0], (us[1] if len(us) > 1 else 0.0)


def scale_material_ms(model, repeats: int) -> float:
    """Median wall time (ms) of a whole-body plus a masked ``scale_material`` (an inclusion re-randomised)."""
    c = model.element_centroids()
    mask = np.linalg.norm(c - c.mean(axis=0), axis=1) < 0.25 * np.ptp(c[:, 0])
    times = []
    for k in range(repeats):
        t0 = time.perf_counter()
        model.scale_material("young", 0.9 + 0.02 * (k % 5))
        model.scale_material("young", 2.0 + 0.1 * (k % 3), mask)
        times.append(time.perf_counter() - t0)
    model.scale_material("young", 1.0)
    return float(np.median(times) * 1e3)


def volumes():
    from surgsim_envs.bench.indent_mesh import graded_slab
    from surgsim_envs.geometry import organ_volume

    slab = organ_volume("slab_inclusion", spacing=0.005)
    yield "palpation slab 5 mm (liver + 20 kPa inclusion)", slab, {1: {"preset": "liver", "young": 20_000.0}}
    yield "bench indentation slab 2 mm (quarter, graded)", graded_slab(0.12, 0.03, 0.002, 0.0124), None


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--repeats", type=int, default=200, help="timed steps per model (median reported)")


def run(args: argparse.Namespace) -> int:
    from surgsim_envs.errors import ConfigError
    from surgsim_envs.tissue import get_material, make

    if args.repeats < 1:
        raise ConfigError(f"surgsim bench calibrated-cost: --repeats must be >= 1, got {args.repeats}")
    import sys

    from tqdm import tqdm

    print(f"load: {os.getloadavg()}")
    for label, vol, regions in tqdm(volumes(), desc="bench calibrated-cost", unit="mesh", file=sys.stderr):
        fixed = np.isclose(vol.nodes[:, 2], vol.nodes[:, 2].min())
        print(f"\n{label}: {vol.n_nodes} nodes, {len(vol.tets)} tets")
        print("model | springs | critical_dt ms (Gershgorin) | exact ms | symplectic us/step | us per sim ms "
              "| implicit us/step (1 ms) | build s | scale_material ms | spring pass us | volume term us")
        kw = {"region_materials": regions} if regions else {}
        names = ("mass_spring", "mass_spring_calibrated")
        built, builds = [], []
        for name in names:
            t0 = time.perf_counter()
            built.append(make(name, vol, get_material("liver"), fixed=fixed, integrator="symplectic", **kw))
            builds.append(time.perf_counter() - t0)
        implicit = [make(name, vol, get_material("liver"), fixed=fixed, integrator="implicit", **kw) for name in names]
        sdts = [m.stable_dt() for m in built]
        dt_of = {id(m): d for m, d in zip(built, sdts)}
        us_s = interleaved_step_us(built, lambda m: dt_of[id(m)], args.repeats)
        us_i = interleaved_step_us(implicit, lambda m: 1e-3, max(args.repeats // 4, 10))
        rows = []
        for k, (name, m) in enumerate(zip(names, built)):
            row = (name, len(m.springs), m.critical_dt() * 1e3, exact_critical_dt(m) * 1e3, us_s[k],
                   us_s[k] * (1e-3 / sdts[k]), us_i[k], builds[k], scale_material_ms(m, 20),
                   *kernel_split_us(m, sdts[k], args.repeats))
            rows.append(row)
            print("{} | {} | {:.3f} | {:.3f} | {:.1f} | {:.0f} | {:.0f} | {:.1f} | {:.1f} | {:.1f} | {:.1f}"
                  .format(*row))
        base, row = rows
        print(f"ratio calibrated/plain: symplectic us per sim ms {row[5] / base[5]:.2f}x, step {row[4] / base[4]:.2f}x, "
              f"critical dt {row[2] / base[2]:.2f}x (exact {row[3] / base[3]:.2f}x), implicit step {row[6] / base[6]:.2f}x")
    print(f"load: {os.getloadavg()}")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
