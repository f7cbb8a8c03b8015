"""``surgsim bench stability``: the largest stable time step per model, integrator, stiffness and resolution.

The test case: a 30 x 30 x 15 mm block of the material, clamped at its bottom face, its top face
pressed by a load that scales with the stiffness (``strain`` x E x top area, 5 % nominal strain by
default, so a soft block is not crushed into inverted elements and a stiff one is not left
unloaded: the limit found is the explicit integrator's, not a large-deformation failure), spread
over the top nodes, every node given a small random velocity (1 mm/s, seeded) so the highest
modes are excited. A time step is *stable* if ``steps`` steps (default 200)
run without the stability guard raising :class:`~surgsim_envs.errors.TissueUnstableError`. The
limit is bracketed by bisection in log(dt) between a stable and an unstable dt until they are within
``rel_tol``; the row reports the largest stable dt found (``dt_limit``, s), the guard's verdict
just above it, and the model's own ``critical_dt()`` estimate beside it. Implicit integrators
usually stay stable up to the search cap ``dt_max`` (``capped = True``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from typing import Any

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError, TissueUnstableError

BLOCK = (0.03, 0.03, 0.015)   # m
DEFAULT_YOUNG = (1e3, 4e3, 2e4, 1e5)          # Pa
DEFAULT_SPACING = (0.0075, 0.005, 0.003)      # m
QUICK_YOUNG = (1e3, 1e4, 1e5)
QUICK_SPACING = (0.0075, 0.005)
LOAD_STRAIN = 0.05                             # nominal compressive strain of the top load


def block_model(model, young: float, spacing: float, integrator: str | None = None, material="liver",
                size=BLOCK, **opts):
    """The clamped test block of ``material`` with Young's modulus ``young`` (Pa) at ``spacing`` (m)."""
    from surgsim_envs.bench.material import model_class
    from surgsim_envs.geometry import box_volume
    from surgsim_envs.materials import get_material

    cls = model_class(model)
    mat = get_material(material).replace(young=float(young))
    vol = box_volume(size, spacing, center=(0.0, 0.0, size[2] / 2.0), name="stability_block")
    fixed = np.isclose(vol.nodes[:, 2], 0.0)
    kwargs = dict(opts)
    if integrator is not None:
        kwargs["integrator"] = integrator
    return cls(vol, mat, fixed=fixed, **kwargs)


def top_load(tissue, strain: float = LOAD_STRAIN) -> float:
    """Downward load (N) on the top face that compresses ``tissue`` by about ``strain``: strain x E x
    area of the top face (from the rest positions of the top nodes; E in Pa)."""
    if not (isinstance(strain, (int, float)) and math.isfinite(strain) and 0 < strain < 0.5):
        raise ConfigError(f"strain must be a nominal strain in (0, 0.5), e.g. 0.05, got {strain!r}")
    x = tissue.rest_positions
    top = np.isclose(x[:, 2], x[:, 2].max())
    area = float(np.ptp(x[top, 0]) * np.ptp(x[top, 1]))
    return float(strain * tissue.material.young * area)


def run_case(tissue, dt: float, steps: int = 200, seed: int = 0, load: float | None = None) -> bool:
    """True if ``steps`` steps at ``dt`` (s) pass the guard; False if it raised TissueUnstableError."""
    return guard_verdict(tissue, dt, steps, seed, load) is None


def guard_verdict(tissue, dt: float, steps: int = 200, seed: int = 0, load: float | None = None):
    """None if ``steps`` steps at ``dt`` (s) pass, else the TissueUnstableError the guard raised.

    load: total downward force on the top nodes (N); default :func:`top_load` (5 % strain)."""
    if load is None:
        load = top_load(tissue)
    elif not (isinstance(load, (int, float)) and math.isfinite(load) and load >= 0):
        raise ConfigError(f"load must be a force >= 0 in N, got {load!r}")
    tissue.reset()
    rng = np.random.default_rng(seed)
    tissue.velocities = np.where(tissue.fixed[:, None], 0.0, rng.normal(0.0, 1e-3, tissue.positions.shape))
    z = tissue.rest_positions[:, 2]
    top = np.isclose(z, z.max())
    forces = np.zeros_like(tissue.positions)
    forces[top, 2] = -load / max(int(top.sum()), 1)
    try:
        for _ in range(steps):
            tissue.step(dt, forces)
    except TissueUnstableError as exc:
        return exc
    return None


def stable_limit(tissue, *, steps: int = 200, dt_max: float = 0.05, dt_min: float = 1e-7,
                 rel_tol: float = 0.05, seed: int = 0) -> dict[str, Any]:
    """Largest stable dt (s) of ``tissue`` by bisection in log(dt).

    Returns {"dt_limit", "dt_unstable" (smallest unstable dt found, or None), "critical_dt",
    "capped" (stable up to dt_max), "error" (the guard's message at dt_unstable)}."""
    if not (0 < dt_min < dt_max and 0 < rel_tol < 1):
        raise ConfigError(f"need 0 < dt_min < dt_max and 0 < rel_tol < 1, got {dt_min}, {dt_max}, {rel_tol}")
    crit = float(tissue.critical_dt())
    if run_case(tissue, dt_max, steps, seed):
        return {"dt_limit": dt_max, "dt_unstable": None, "critical_dt": crit, "capped": True, "error": "",
                "load": top_load(tissue)}
    lo = min(0.5 * crit, dt_max) if math.isfinite(crit) and crit > 0 else 1e-4
    hi = dt_max
    while not run_case(tissue, lo, steps, seed):
        hi, lo = lo, lo / 4.0
        if lo < dt_min:
            raise ConfigError(f"model '{tissue.name}' is unstable even at dt={lo:.3g} s")
    while hi / lo > 1.0 + rel_tol:
        mid = math.sqrt(lo * hi)
        if run_case(tissue, mid, steps, seed):
            lo = mid
        else:
            hi = mid
    verdict = guard_verdict(tissue, hi, steps, seed)
    error = verdict.reason if verdict is not None else ""
    return {"dt_limit": lo, "dt_unstable": hi, "critical_dt": crit, "capped": False, "error": error,
            "load": top_load(tissue)}


def stability_map(models=None, youngs=DEFAULT_YOUNG, spacings=DEFAULT_SPACING, steps: int = 200,
                  dt_max: float = 0.05, progress: bool = True) -> list[dict]:
    """Rows {model, integrator, young, spacing, nodes, dt_limit, dt_unstable, critical_dt, capped}."""
    from tqdm import tqdm

    from surgsim_envs.bench.speed import available_models

    classes = [(n, c) for n, c in available_models() if models is None or n in models]
    jobs = [(c, integ, e, s) for _, c in classes for integ in c.integrators for e in youngs for s in spacings]
    rows = []
    with tqdm(jobs, desc="bench stability", unit="case", file=sys.stderr, disable=not progress) as bar:
        for cls, integ, e, s in bar:
            bar.set_postfix_str(f"{cls.name}/{integ} E={e:g} h={s:g}")
            try:
                tissue = block_model(cls, e, s, integ)
                row = stable_limit(tissue, steps=steps, dt_max=dt_max)
            except Exception as exc:  # keep mapping the others
                print(f"surgsim bench stability: {cls.name}/{integ} E={e} h={s} failed: {exc}", file=sys.stderr)
                continue
            rows.append({"model": cls.name, "integrator": integ, "young": float(e), "spacing": float(s),
                         "nodes": tissue.n_nodes, **row})
    return rows


def plot_map(rows: list[dict], path: str) -> None:
    """One panel per spacing: dt limit (markers) and critical-dt estimate (dashed) against E."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    spacings = sorted({r["spacing"] for r in rows})
    fig, axes = plt.subplots(1, len(spacings), figsize=(4.2 * len(spacings), 3.8), sharey=True, squeeze=False)
    series = sorted({(r["model"], r["integrator"]) for r in rows})
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, s in zip(axes[0], spacings):
        for k, (m, integ) in enumerate(series):
            sub = sorted((r for r in rows if r["spacing"] == s and r["model"] == m and r["integrator"] == integ),
                         key=lambda r: r["young"])
            if not sub:
                continue
            e = [r["young"] for r in sub]
            lim = [r["dt_limit"] for r in sub]
            c = colors[k % len(colors)]
            ax.plot(e, lim, "o-", color=c, label=f"{m}/{integ} measured")
            capped = [r for r in sub if r["capped"]]
            if capped:
                ax.plot([r["young"] for r in capped], [r["dt_limit"] for r in capped], "^", color=c,
                        ms=max(5, 13 - 3 * k), mfc="none" if k % 2 else c, mew=1.5)   # overlapping caps stay visible
            crit = [r["critical_dt"] if math.isfinite(r["critical_dt"]) else np.nan for r in sub]
            if integ in ("symplectic", "explicit"):
                ax.plot(e, crit, "--", color=c, alpha=0.7, label=f"{m}/{integ} critical_dt()")
        ax.axhline(1e-3, color="gray", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("Young's modulus E (Pa)")
        ax.set_title(f"spacing {s * 1e3:g} mm")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].set_ylabel("largest stable dt (s)")
    axes[0][-1].legend(fontsize=7, loc="lower left")
    fig.suptitle(f"Clamped 30 x 30 x 15 mm block, top load = {LOAD_STRAIN:.0%} strain x E x area; "
                 "triangles: stable at the search cap; dotted: 1 ms", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="surgsim-out/stability", help="output directory (JSON + PNG)")
    parser.add_argument("--quick", action="store_true", help="smaller sweep (3 stiffnesses x 2 spacings)")
    parser.add_argument("--models", default=None, help="comma-separated model names (default: all registered)")
    parser.add_argument("--steps", type=int, default=200, help="steps per trial (default 200)")
    parser.add_argument("--dt-max", type=float, default=0.05, help="search cap in s (default 0.05)")
    parser.add_argument("--json", action="store_true", help="also print the rows as JSON")


def run(args: argparse.Namespace) -> int:
    from surgsim_envs.bench.speed import available_models

    # every flag is checked before anything is computed or written: a typo must not overwrite a map
    validate.integer(args.steps, "--steps", lo=10, hi=100_000, fix="steps per trial, e.g. 200")
    validate.real(args.dt_max, "--dt-max", lo=1e-6, hi=1.0, unit="s", fix="the search cap, e.g. 0.05")
    models = None if not args.models else [m.strip() for m in args.models.split(",") if m.strip()]
    if args.models is not None:
        known = [n for n, _ in available_models()]
        unknown = [m for m in models or [] if m not in known]
        if unknown or not models:
            raise ConfigError(f"--models {args.models!r}: unknown model(s) {unknown}; mappable models: {known} "
                              "(nothing was written)")
    youngs, spacings = (QUICK_YOUNG, QUICK_SPACING) if args.quick else (DEFAULT_YOUNG, DEFAULT_SPACING)
    rows = stability_map(models, youngs, spacings, steps=args.steps, dt_max=args.dt_max)
    if not rows:
        raise ConfigError(f"every case of the stability map failed (see above); {args.out}/stability.json was left "
                          "as it was")
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "stability.json"), "w") as fh:
        json.dump(rows, fh, indent=2)
    if rows:
        plot_map(rows, os.path.join(args.out, "stability.png"))
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        print(f"{'model':<12} {'integrator':<11} {'E (Pa)':>9} {'h (mm)':>7} {'nodes':>6} {'dt limit':>10} {'critical':>10}")
        for r in rows:
            lim = f">={r['dt_limit']:.3g}" if r["capped"] else f"{r['dt_limit']:.3g}"
            print(f"{r['model']:<12} {r['integrator']:<11} {r['young']:>9.3g} {r['spacing'] * 1e3:>7.3g} "
                  f"{r['nodes']:>6} {lim:>10} {r['critical_dt']:>10.3g}")
        print(f"wrote {args.out}/stability.json and stability.png")
    return 0
