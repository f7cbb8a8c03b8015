"""How much LayeredPalpation-v0's force over the nodule depends on where the nodule sits on the lattice.

The nodule and the press over it are moved by (i, j) quarters of the spacing (i, j = 0-3, 16
positions) from the probe set's site, and the three presses over the nodule (2.5, 3.5, 4.5 mm) are
compared with the shipped reference's presses over the nodule: the reference's force over the
nodule does not depend on where the nodule sits to about 1 % (its 1 mm levels at (2, 1) and
(-1.5, 0.5) cm read 1.0-1.1 % apart), so one reference serves every position.

    python scripts/layered_nodule_offsets.py --model fem_hex --spacings 0.005,0.004,0.0033333333333333335,0.0025 \
        --plot docs/img/layered_nodule_offsets.png

Prints per spacing the smallest and largest error over the 16 positions, overall and per depth;
``--plot FILE`` draws them (a bar per depth from the smallest to the largest error, the task's
tolerance and the default spacing marked). ``--volumes`` prints instead, per spacing, the range over
the same 16 positions of the nodule's volume on the lattice (each cell's volume times the share of
its material points inside the sphere) over the sphere's, for the task's rule and for the cells'
centres, with no solve.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np

from surgsim_envs.bench.probe_sets import layered_palpation as lp
from surgsim_envs.tissue.task_table import TASK_TABLE_PATH


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", default="fem_hex", choices=lp.MODELS)
    ap.add_argument("--spacings", default="0.005,0.004,0.0033333333333333335,0.0025", help="comma-separated, m")
    ap.add_argument("--plot", default=None, help="write a PNG of the error ranges here")
    ap.add_argument("--volumes", action="store_true", help="print the nodule's volume ranges only (no presses)")
    args = ap.parse_args()
    if args.volumes:
        volumes(args.model, [float(v) for v in args.spacings.split(",")])
        return
    ranges = {}
    with open(TASK_TABLE_PATH) as fh:
        ref = json.load(fh)["references"][lp.TASK]["forces_N"]
    over = [k for k in ref if "/over/" in k]
    for h in (float(v) for v in args.spacings.split(",")):
        t0, errors = time.time(), []
        for ox in np.arange(4) * h / 4:
            for oy in np.arange(4) * h / 4:
                pos = (lp.NODULE_XY[0] + ox, lp.NODULE_XY[1] + oy)
                probes = dataclasses.replace(lp.FULL, inclusions=(dataclasses.replace(lp.NODULE, position=pos),))
                f = lp.measure(lp.TASK, args.model, h, probes)["forces_N"]
                errors.append([f[k] / ref[k] - 1 for k in over])
        e = 100 * np.array(errors)
        ranges[h] = (e.min(0), e.max(0))
        depths = ", ".join(f"{k.rsplit('/', 1)[-1]} {a:+.1f} to {b:+.1f}" for k, a, b in zip(over, e.min(0), e.max(0)))
        print(f"{args.model} at {h * 1e3:.3g} mm, 16 positions: {e.min():+.1f} to {e.max():+.1f} % (per depth "
              f"{depths}); {time.time() - t0:.0f} s", flush=True)
    if args.plot:
        plot(ranges, [k.rsplit("/", 1)[-1] for k in over], args.model, args.plot)


def volumes(model: str, spacings: list) -> None:
    """The nodule's volume on the lattice over the sphere's, at the 16 positions (module docstring)."""
    import math

    import gymnasium as gym

    import surgsim_envs  # noqa: F401  (registers the tasks)

    for h in spacings:
        env = gym.make(lp.TASK, model=model, spacing=h, disable_env_checker=True).unwrapped
        points, centres = env.tissue.material_points(), env.tissue.element_centroids()
        cell = env.tissue.element_vertices()
        size = cell.max(axis=1) - cell.min(axis=1)
        element_volume = size.prod(axis=1) if cell.shape[1] == 8 else np.abs(np.linalg.det(cell[:, 1:] - cell[:, :1])) / 6
        r = env.config.nodule_radius
        sphere = 4.0 / 3.0 * math.pi * r ** 3
        rule, centre = [], []
        for ox in np.arange(4) * h / 4:
            for oy in np.arange(4) * h / 4:
                env.reset(seed=0, options={"nodule_position": (lp.NODULE_XY[0] + ox, lp.NODULE_XY[1] + oy)})
                inside = np.linalg.norm(points - env.nodule, axis=2) < r
                rule.append(float((inside.mean(axis=1) * element_volume).sum() / sphere))
                centre.append(float(((np.linalg.norm(centres - env.nodule, axis=1) < r) * element_volume).sum() / sphere))
        env.close()
        print(f"{model} at {h * 1e3:.3g} mm, 16 positions: the nodule's volume / the sphere's {min(rule):.3f} to "
              f"{max(rule):.3f} ({points.shape[1]} point(s) an element); the cells' centres {min(centre):.3f} to "
              f"{max(centre):.3f}", flush=True)


def plot(ranges: dict, depths: list, model: str, path: str) -> None:
    """Error ranges (%) per spacing and press depth, with the task's tolerance and default spacing."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from surgsim_envs.bench.choose import task_tolerance
    from surgsim_envs.envs.layered_palpation import LayeredPalpationConfig

    tol = 100 * task_tolerance(lp.TASK)
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    for j, depth in enumerate(depths):
        x = [1e3 * h + 0.12 * (j - 1) for h in ranges]
        lo = [r[0][j] for r in ranges.values()]
        hi = [r[1][j] for r in ranges.values()]
        ax.vlines(x, lo, hi, lw=6, color=f"C{j}", label=f"press to {depth}")
    for sign in (-1, 1):
        ax.axhline(sign * tol, color="k", ls="--", lw=1)
    ax.axhline(0, color="0.6", lw=0.8)
    default = LayeredPalpationConfig()
    if default.model == model:
        ax.axvline(1e3 * default.spacing, color="0.4", ls=":", lw=1)
        ax.text(1e3 * default.spacing, -tol - 2, " default", color="0.3", va="top")
    ax.set_xlabel("lattice spacing (mm)")
    ax.set_ylabel("force error over the nodule (%)")
    ax.set_title(f"{lp.TASK} ({model}): the nodule at 16 positions within a cell", fontsize=9)
    ax.set_ylim(-tol - 15, tol + 12)
    ax.legend(fontsize=8, loc="upper center", ncol=len(depths), frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print("wrote", path)


if __name__ == "__main__":
    main()
