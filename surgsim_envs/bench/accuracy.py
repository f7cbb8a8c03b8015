"""``surgsim bench accuracy``: force error against cost for every model, integrator and resolution.

Every registered model (built-ins and plugins) that declares the capability ``forces`` is run with
each of its integrators; models without it are skipped with the CapabilityError naming what
they lack (no model names in this module).

Scene "indent": a rigid sphere (R = 5 mm) pressed into a 30 mm liver slab (E = 4 kPa, nu = 0.45)
bonded to a rigid base (:func:`surgsim_envs.bench.material.indent`, graded quarter mesh). Error:
mean relative force error against Dimitriadis et al. (2002) over depths in [d_v/4, d_v], d_v the
reference's validity depth (1.5 mm here); ``self_error`` is the same against the model's own
finest resolution (its converged solution). Cost: microseconds of compute per simulated
millisecond (wall time of one physics step, contact + tissue, times the steps per ms at the
model's stable dt). Outputs ``accuracy.json`` (the table :func:`surgsim_envs.tissue.resolution.choose` reads)
and ``accuracy.png`` (log-log, Pareto front marked). Shape error (``shape_rms`` etc., m; chart
``accuracy_shape.png``): signed distances of the deformed top surface at the deepest depth to the
most accurate model's finest surface under the same load (:mod:`surgsim_envs.bench.shape_error`,
Vandewalle et al. 2003 sec. 2.2).

Baselines, in the same process on the same scene (:func:`surgsim_envs.bench.mujoco_flex.flex_indent`):
MuJoCo's own 3-D flex with built-in elasticity, ``mujoco_flex_full`` (three dofs per vertex, the
same graded mesh whole, label = spacing in mm) and ``mujoco_flex_trilinear`` (dofs on a
``cellcount``^3 interpolation grid, label ``cN``), the sphere pressed in steps and held until the
flex settles, force = sum of the sphere's contact forces, depth = sphere bottom below the
undeformed surface (so MuJoCo's soft-contact penetration, reported as ``penetration``, counts
as compliance). Cost = median wall time of one ``mj_step`` at 1 ms. Baseline rows carry
``"baseline": true`` and are never picked by :func:`surgsim_envs.tissue.resolution.choose`.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys


from surgsim_envs.bench.accuracy_scene import MATERIAL, RADIUS, THICKNESS, add_self_error, force_error
from surgsim_envs.bench.references import dimitriadis_force, dimitriadis_valid_depth
from surgsim_envs.bench.shape_error import add_shape_error, plot_shape_axis
from surgsim_envs.tissue.capabilities import CapabilityError

#: the capability the indentation needs (nodal forces in, positions out); asked of every registered model
NEEDS = "forces"

SPACINGS = (0.003, 0.002, 0.0015, 0.001, 0.0007)
QUICK_SPACINGS = (0.003, 0.002, 0.0013)
FLEX_SPACINGS = (0.006, 0.004, 0.003)        # m, mujoco_flex_full (whole slab: 1,125 / 2,527 / 3,528 vertices)
QUICK_FLEX_SPACINGS = (0.006, 0.004)
FLEX_CELLCOUNTS = (1, 2, 4, 8)               # mujoco_flex_trilinear interpolation grid (cells per axis)
QUICK_FLEX_CELLCOUNTS = (1, 2, 4)
FLEX_COLLISION_SPACING = 0.004               # m, the trilinear flex's (collision) mesh under the sphere
#: compute per simulated millisecond at which a model runs in real time (us); drawn on the chart
REAL_TIME_US_PER_MS = 1000.0
#: force error an "accurate" model must reach (<= 5 % at real time); drawn on the chart
TARGET_ERROR = 0.05


def sweep(models=None, spacings=SPACINGS, progress: bool = True, time_steps: int = 10) -> list[dict]:
    """Rows {scene, model, integrator, spacing, nodes, dt, us_per_step, us_per_ms, error, self_error}."""
    from tqdm import tqdm

    from surgsim_envs.bench.material import indent
    from surgsim_envs.bench.speed import available_models
    from surgsim_envs.tissue import get_material

    mat = get_material(MATERIAL).replace(relax_fraction=0.0, nonlinear=0.0)  # elastic: the reference is
    dv = dimitriadis_valid_depth(RADIUS, THICKNESS)
    classes = []
    for n, c in available_models():
        if models is not None and n not in models:
            continue
        try:   # every registered model that takes nodal forces; the others say what they lack
            c.require(NEEDS, task="surgsim bench accuracy (sphere indentation)")
        except CapabilityError as exc:
            print(f"surgsim bench accuracy: skipping: {exc}", file=sys.stderr)
            continue
        classes.append((n, c))
    jobs = [(c, integ, s) for _, c in classes for integ in c.integrators for s in spacings]
    rows = []
    with tqdm(jobs, desc="bench accuracy", unit="case", file=sys.stderr, disable=not progress) as bar:
        for cls, integ, s in bar:
            bar.set_postfix_str(f"{cls.name}/{integ} h={s * 1e3:g} mm")
            # a model calibrated elsewhere (not on this scene) runs with its calibrated options
            calibrated = dict(getattr(cls, "accuracy_options", {}) or {})
            try:
                res = indent(cls, mat, indenter_radius=RADIUS, depth=dv, thickness=THICKNESS, spacing=s,
                             n_depths=8, integrator=integ, time_steps=time_steps, **calibrated)
            except Exception as exc:  # keep sweeping
                print(f"surgsim bench accuracy: {cls.name}/{integ} h={s}: {exc}", file=sys.stderr)
                continue
            ref = dimitriadis_force(res.depth, RADIUS, mat.young, mat.poisson, THICKNESS, bonded=True)
            rows.append({"scene": "indent", "model": cls.name, "integrator": integ, "spacing": s,
                         "nodes": res.nodes, "dt": res.dt, "us_per_step": res.us_per_step, "us_per_ms": res.us_per_ms,
                         "error": force_error(res.depth, res.force, ref, dv), "depth": res.depth.tolist(),
                         "force": res.force.tolist(), "_surface": res.top_surface,
                         **({"calibration": calibrated} if calibrated else {})})
    add_self_error(rows)
    add_shape_error(rows)          # shape_mu/sigma/rms vs the most accurate finest surface (bench/shape_error.py)
    return rows


def flex_sweep(spacings=FLEX_SPACINGS, cellcounts=FLEX_CELLCOUNTS, progress: bool = True) -> list[dict]:
    """Rows of the MuJoCo flex baselines on the same scene (``"baseline": True``; see module doc)."""
    from tqdm import tqdm

    from surgsim_envs.bench.mujoco_flex import flex_indent
    from surgsim_envs.tissue import get_material

    mat = get_material(MATERIAL).replace(relax_fraction=0.0, nonlinear=0.0)
    dv = dimitriadis_valid_depth(RADIUS, THICKNESS)
    jobs = [("full", s, 1) for s in spacings] + [("trilinear", FLEX_COLLISION_SPACING, c) for c in cellcounts]
    rows = []
    with tqdm(jobs, desc="bench accuracy (MuJoCo flex)", unit="case", file=sys.stderr, disable=not progress) as bar:
        for dof, s, cells in bar:
            bar.set_postfix_str(f"{dof} h={s * 1e3:g} mm" + (f" cells={cells}" if dof != "full" else ""))
            try:
                res = flex_indent(dof, mat, indenter_radius=RADIUS, depth=dv, thickness=THICKNESS, spacing=s,
                                  cellcount=cells, n_depths=8)
            except Exception as exc:  # keep sweeping
                print(f"surgsim bench accuracy: mujoco_flex_{dof} h={s} cells={cells}: {exc}", file=sys.stderr)
                continue
            ref = dimitriadis_force(res.depth, RADIUS, mat.young, mat.poisson, THICKNESS, bonded=True)
            full = dof == "full"
            rows.append({"scene": "indent", "model": f"mujoco_flex_{dof}", "integrator": "discrete",
                         # trilinear: resolution = interpolation cell width (the mesh only collides)
                         "spacing": s if full else res.info["width"] / cells, "nodes": res.nodes, "dofs": res.dofs,
                         "cellcount": cells, "label": f"{s * 1e3:g}" if full else f"c{cells}", "dt": res.dt,
                         "us_per_step": res.us_per_step, "us_per_ms": res.us_per_ms,
                         "error": force_error(res.depth, res.force, ref, dv), "depth": res.depth.tolist(),
                         "force": res.force.tolist(), "penetration": res.penetration.tolist(), "baseline": True})
    add_self_error(rows)
    return rows


def pareto(rows: list[dict]) -> list[dict]:
    """Rows not dominated in (us_per_ms, error): nobody is both cheaper and more accurate."""
    pts = [r for r in rows if math.isfinite(r["us_per_ms"]) and math.isfinite(r["error"])]
    front = [r for r in pts if not any(q is not r and q["us_per_ms"] <= r["us_per_ms"] and q["error"] <= r["error"]
                                       and (q["us_per_ms"] < r["us_per_ms"] or q["error"] < r["error"]) for q in pts)]
    return sorted(front, key=lambda r: r["us_per_ms"])


def plot(rows: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10.0, 5.6))
    series = sorted({(r["model"], r["integrator"]) for r in rows}, key=lambda k: (k[0].startswith("mujoco"), k))
    colours = plt.get_cmap("tab20").colors            # one colour per series (tab10 repeats beyond 10)
    for n, (m, integ) in enumerate(series):
        sub = sorted((r for r in rows if r["model"] == m and r["integrator"] == integ and math.isfinite(r["us_per_ms"])),
                     key=lambda r: r["spacing"])
        if not sub:
            continue
        style = "s--" if sub[0].get("baseline") else "o-"
        name = f"{m} ({sub[0].get('peer', 'MuJoCo')} baseline)" if sub[0].get("baseline") else f"{m} / {integ}"
        ax.plot([r["us_per_ms"] for r in sub], [max(r["error"], 1e-4) for r in sub], style, label=name, ms=5,
                color=colours[(2 * n) % 20 if n < 10 else (2 * n + 1) % 20])
        for r in sub:
            ax.annotate(r.get("label", f"{r['spacing'] * 1e3:g}"), (r["us_per_ms"], max(r["error"], 1e-4)),
                        fontsize=7, textcoords="offset points", xytext=(4, 3))
    front = pareto(rows)
    if front:
        ax.step([r["us_per_ms"] for r in front], [max(r["error"], 1e-4) for r in front], where="post", color="k",
                lw=2, alpha=0.35, label="Pareto front")
        ax.plot([r["us_per_ms"] for r in front], [max(r["error"], 1e-4) for r in front], "o", mfc="none",
                mec="k", ms=10, mew=1.2)
    ax.axvline(REAL_TIME_US_PER_MS, color="tab:red", ls=":", lw=1.5, label="real time (1,000 us per simulated ms)")
    ax.axhline(TARGET_ERROR, color="tab:green", ls=":", lw=1.5, label=f"{TARGET_ERROR:.0%} force error")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("cost: us of compute per simulated ms")
    ax.set_ylabel("force error vs Dimitriadis (fraction)")
    ax.set_title("Sphere indentation of a bonded 30 mm liver slab\n(labels: mm spacing under the sphere; "
                 "cN: trilinear flex with N cells per axis; circled: Pareto front)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)  # outside: no point hidden
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="surgsim-out/accuracy", help="output directory (accuracy.json, accuracy.png)")
    parser.add_argument("--quick", action="store_true", help="three resolutions only (about 3 min, 2 of them the MuJoCo flex baselines)")
    parser.add_argument("--models", default=None, help="comma-separated model names (default: all registered)")
    parser.add_argument("--no-baselines", action="store_true",
                        help="skip the MuJoCo flex baselines (mujoco_flex_full/_trilinear)")
    parser.add_argument("--scene", choices=("indent", "layered"), default="indent",
                        help="indent: sphere into a liver slab vs Dimitriadis (default); layered: flat punch into an "
                             "abdominal wall vs converged fem_static (surgsim_envs.bench.accuracy_layered)")


def run(args: argparse.Namespace) -> int:
    if getattr(args, "scene", "indent") == "layered":
        from surgsim_envs.bench.accuracy_layered import run_scene

        return run_scene(args)
    from surgsim_envs import tissue, validate

    models = validate.name_list(args.models, "--models",
                                list(tissue.names()) + ["mujoco_flex_full", "mujoco_flex_trilinear"])
    rows = sweep(models, QUICK_SPACINGS if args.quick else SPACINGS)
    if not getattr(args, "no_baselines", False):
        full = models is None or "mujoco_flex_full" in models
        tri = models is None or "mujoco_flex_trilinear" in models
        rows += flex_sweep((QUICK_FLEX_SPACINGS if args.quick else FLEX_SPACINGS) if full else (),
                           (QUICK_FLEX_CELLCOUNTS if args.quick else FLEX_CELLCOUNTS) if tri else ())
        from surgsim_envs.bench import pybullet_peer  # PyBullet's FEM and mass-spring soft bodies

        rows += pybullet_peer.peer_sweep(pybullet_peer.QUICK_SPACINGS if args.quick else pybullet_peer.SPACINGS, models)
    os.makedirs(args.out, exist_ok=True)
    table = {"scene": "indent", "radius": RADIUS, "thickness": THICKNESS, "material": MATERIAL,
             "reference": "dimitriadis bonded", "rows": rows}
    with open(os.path.join(args.out, "accuracy.json"), "w") as fh:
        json.dump(table, fh, indent=1)
    if rows:
        plot(rows, os.path.join(args.out, "accuracy.png"))
        plot_shape_axis(rows, os.path.join(args.out, "accuracy_shape.png"))
    front = {id(r) for r in pareto(rows)}
    print(f"{'model':<22} {'integrator':<11} {'res':>5} {'nodes':>6} {'us/ms':>10} {'error':>7} {'self':>7} "
          f"{'pen mm':>6} {'shape mm':>8}")
    for r in rows:
        mark = " *" if id(r) in front else ""
        pen = f"{max(r['penetration']) * 1e3:6.3f}" if "penetration" in r else " " * 6
        res = r.get("label", f"{r['spacing'] * 1e3:g}")
        print(f"{r['model']:<22} {r['integrator']:<11} {res:>5} "
              f"{r['nodes']:>6} {r['us_per_ms']:>10.4g} {r['error']:>7.3f} {r['self_error']:>7.3f} {pen} "
              f"{r.get('shape_rms', math.nan) * 1e3:>8.4f}{mark}")
    print("(res: mm spacing under the sphere, cN: trilinear cells per axis; pen: MuJoCo contact penetration at "
          f"the deepest point; * = Pareto front) wrote {args.out}/accuracy.json and accuracy.png")
    return 0
