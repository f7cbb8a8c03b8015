"""Figures of docs/models/growth.md (Vandewalle et al. 2003): Fig. 3 (cube growth vs k), Fig. 4 (iterations vs
alpha), Fig. 5 (nu, k sweep on the synthetic maxillofacial case), Figs. 6/7 (basic vs growth).

    PYTHONPATH=. python scripts/growth_figures.py --out docs/img [--skip-sweep]
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from surgsim_envs import tissue  # noqa: E402
from surgsim_envs.errors import GrowthDivergedError, GrowthNotConvergedError  # noqa: E402
from surgsim_envs.geometry import box_volume  # noqa: E402
from surgsim_envs.tissue.growth import GrowthSolver, mesh_volume  # noqa: E402

E, NU = 3000.0, 0.25


def stretched_cube(spacing=0.0025, stretch=0.001):
    vol = box_volume((0.02, 0.02, 0.02), spacing=spacing)
    m = tissue.make("fem", vol, {"young": E, "poisson": NU, "density": 1000.0}, formulation="standard",
                    corotational=False, integrator="implicit")
    x = vol.nodes
    left, right = np.isclose(x[:, 0], x[:, 0].min()), np.isclose(x[:, 0], x[:, 0].max())
    m.set_fixed(left, x[left] + [-stretch, 0, 0])
    m.set_fixed(right, x[right] + [stretch, 0, 0])
    return m


def fig3(out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    m = stretched_cube()
    solver = GrowthSolver.from_model(m)
    v0 = mesh_volume(m.rest_positions, m.tets)
    states = [("rest", m.rest_positions, None), ("basic model (no growth)", solver.rest_positions + solver.basic().reshape(-1, 3), None)]
    rows = []
    for k in (0, 5, 10, 20):
        res = solver.grow(k)
        states.append((f"k = {k}", res.positions, res))
        rows.append({"k": k, "iterations": res.iterations, "volume_ratio": mesh_volume(res.positions, m.tets) / v0})
    lim = max(np.abs(p).max() for _, p, _ in states) * 1e3
    fig = plt.figure(figsize=(3.2 * len(states), 3.6))
    for i, (title, pos, res) in enumerate(states):
        ax = fig.add_subplot(1, len(states), i + 1, projection="3d")
        tri = pos[m.surface] * 1e3
        shade = 0.35 + 0.6 * np.abs(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
                                    @ np.array([0.3, -0.5, 0.8])) / (np.linalg.norm(
            np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1) + 1e-30)
        ax.add_collection3d(Poly3DCollection(tri, facecolors=plt.cm.Oranges(shade), edgecolors=(0, 0, 0, 0.15), lw=0.2))
        for a in "xyz":
            getattr(ax, f"set_{a}lim")(-lim, lim)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(20, -60)
        ax.set_axis_off()
        vr = mesh_volume(pos, m.tets) / v0
        ax.set_title(f"{title}\nvolume x{vr:.3f}", fontsize=9)
    fig.suptitle("Fig. 3: a 20 mm cube stretched 1 mm to the left and to the right (E = 3 kPa, nu = 0.25); "
                 "growth equilibria for k = 0, 5, 10, 20", fontsize=10)
    fig.savefig(os.path.join(out, "growth_fig3_cube.png"), dpi=110, bbox_inches="tight")
    plt.close(fig)
    return rows


def fig4(out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    solver = GrowthSolver.from_model(stretched_cube())
    auto, safe = solver.alpha_bounds()
    spectral = solver.spectral_alpha_limit(100)
    alphas = np.round(np.linspace(0.05, 1.25, 25) * safe, 8)
    its, status = [], []
    for a in alphas:
        try:
            its.append(solver.grow(20, float(a), max_iter=20000).iterations)
            status.append("converged")
        except GrowthDivergedError:
            its.append(np.nan)
            status.append("diverged")
        except GrowthNotConvergedError:
            its.append(np.nan)
            status.append("not converged")
    its = np.array(its, float)
    conv = np.array([s == "converged" for s in status])
    fig, ax = plt.subplots(figsize=(7, 4.2))
    ax.plot(alphas[conv] * 1e3, its[conv], "o-", label="iterations to converge (k = 20, tol 1e-5)")
    div = np.array([s == "diverged" for s in status])
    if div.any():
        ax.plot(alphas[div] * 1e3, np.full(div.sum(), np.nanmax(its) * 0.5), "rx", ms=9, mew=2, label="diverged")
    ax.axvline(auto * 1e3, color="g", ls="--", label=f"alpha='auto' = 2/(2mu+3kappa) = {auto * 1e3:.3f}e-3 1/Pa")
    ax.axvline(safe * 1e3, color="k", ls=":", label=f"bound 2/(3 kappa) = {safe * 1e3:.4f}e-3 1/Pa")
    ax.axvline(spectral * 1e3, color="r", ls="-.", lw=0.8, label=f"mesh limit 2/lambda_max = {spectral * 1e3:.4f}e-3 1/Pa")
    ax.set_yscale("log")
    ax.set_xlabel("stability factor alpha (1e-3 1/Pa)")
    ax.set_ylabel("iterations")
    ax.set_title("Fig. 4: iterations against alpha (20 mm cube, 2.5 mm tets, E = 3 kPa, nu = 0.25)", fontsize=9)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "growth_fig4_alpha.png"), dpi=110)
    plt.close(fig)
    return {"alphas": alphas.tolist(), "iterations": [None if np.isnan(i) else int(i) for i in its], "status": status,
            "alpha_auto": auto, "alpha_bound": safe, "alpha_spectral": spectral}


def fig5_6(out, skip_sweep):
    from surgsim_envs.planning.validation_report import comparison_figure
    from surgsim_envs.geometry.surface_error import surface_error
    from surgsim_envs.planning.maxillofacial import DistractionCase
    from surgsim_envs.planning.sweep import TRUTH, grown_skin, plot_sweep, sweep

    case = DistractionCase()
    ref = grown_skin(case, 0.0025, *TRUTH)
    m = case.model(0.004, 0.25)
    solver = GrowthSolver.from_model(m)
    skin = case.skin_faces(m.volume)
    res = solver.grow(20)
    entries = []
    summary = {}
    for label, pos in (("basic model", res.basic_positions), ("growth model (nu = 0.25, k = 20)", res.positions)):
        err = surface_error(pos, skin, ref[0], ref[1])
        entries.append((label, pos, skin, err))
        summary[label] = err.summary()
    comparison_figure(os.path.join(out, "growth_fig6_comparison.png"), entries, suptitle=(
        f"Skin error against a SYNTHETIC reference (growth model at nu = {TRUTH[0]}, k = {TRUTH[1]:g}, 2.5 mm mesh); "
        "predictions with the paper's optimum nu = 0.25, k = 20 on a 4 mm mesh"))
    if not skip_sweep:
        result = sweep(case, spacing=0.004, reference_spacing=0.0025, reference=ref)
        plot_sweep(result, os.path.join(out, "growth_fig5_sweep.png"))
        summary["sweep"] = result.to_dict()
    return summary


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--out", default="docs/img")
    p.add_argument("--skip-sweep", action="store_true")
    p.add_argument("--only", default="3,4,5")
    args = p.parse_args()
    os.makedirs(args.out, exist_ok=True)
    report = {}
    if "3" in args.only:
        report["fig3"] = fig3(args.out)
        print(json.dumps(report["fig3"]))
    if "4" in args.only:
        report["fig4"] = fig4(args.out)
        print(json.dumps({k: v for k, v in report["fig4"].items() if k != "alphas"}))
    if "5" in args.only:
        report["fig5_6"] = fig5_6(args.out, args.skip_sweep)
    with open(os.path.join(args.out, "growth_figures.json"), "w") as fh:
        json.dump(report, fh, indent=1)


if __name__ == "__main__":
    main()
