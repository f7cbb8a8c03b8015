"""``surgsim material indent|relax|slip``: run a virtual material test and print the curve.

    surgsim material indent --model fem --set young=5000 --set poisson=0.45 --radius 0.005 \
        --depth 0.003 --thickness 0.03 --json
    surgsim material relax --model mass_spring --material liver --strain 0.05 --json
    surgsim material slip --model mass_spring --mu 0.6 --json

``slip`` pulls until the grasp slides (docs/material_tests.md, "Slip onset") and prints progress on
stderr while a slow model pulls.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from surgsim_envs.errors import ConfigError


def parse_sets(items, base: str):
    """--set key=value pairs on top of preset ``base`` -> material dict (the preset checked by name)."""
    from surgsim_envs.materials import get_material

    try:
        get_material(base)
    except (ConfigError, TypeError, ValueError, KeyError) as exc:
        raise ConfigError(f"--material {base!r}: {exc}") from None
    out = {"preset": base}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep:
            raise ConfigError(f"--set expects key=value (e.g. young=5000), got {item!r}")
        try:
            out[key.strip()] = float(value)
        except ValueError:
            raise ConfigError(f"--set {key}: value {value!r} is not a number (SI units)") from None
    return out


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="test", metavar="TEST", required=True)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--model", default="fem", help="registered model name (default fem)")
    common.add_argument("--material", default=None,
                        help="material preset the --set values modify (default liver; slip: a 20 kPa gel)")
    common.add_argument("--set", action="append", metavar="KEY=VALUE", help="material field, e.g. young=5000")
    common.add_argument("--integrator", default=None, help="model integrator (default: the test's choice)")
    common.add_argument("--spacing", type=float, default=None, help="mesh spacing in m")
    common.add_argument("--json", action="store_true", help="print the result as JSON")
    common.add_argument("--plot", default=None, metavar="FILE.png", help="save a plot of the curve")
    p = sub.add_parser("indent", parents=[common], help="rigid sphere into a slab on a rigid base")
    p.add_argument("--radius", type=float, default=0.005, help="sphere radius m")
    p.add_argument("--depth", type=float, default=0.003, help="final depth m")
    p.add_argument("--thickness", type=float, default=0.03, help="slab thickness m")
    p.add_argument("--width", type=float, default=None, help="slab width m (default 4 x thickness)")
    p.add_argument("--unbonded", action="store_true", help="slab slides on its base (fixed in z only)")
    p.add_argument("--points", type=int, default=12, help="number of depths")
    r = sub.add_parser("relax", parents=[common], help="ramp-and-hold compression of a block")
    r.add_argument("--strain", type=float, default=0.05)
    r.add_argument("--ramp-time", type=float, default=0.2, help="s")
    r.add_argument("--hold-time", type=float, default=3.0, help="s")
    s = sub.add_parser("slip", parents=[common], help="three-jaw grasp, then a ramped pull")
    s.add_argument("--mu", type=float, default=0.6, help="jaw friction coefficient")
    s.add_argument("--max-pull-time", type=float, default=None,
                   help="s, longest pull before the rig reports that the grasp never slid (default 5)")


def _slip_progress(every_s: float = 10.0):
    """progress callback for :func:`surgsim_envs.bench.material.slip`: a line on stderr every
    ``every_s`` seconds of wall time (a slow model's pull can take minutes)."""
    start = last = time.perf_counter()

    def report(t: float, pull: float, cap: float) -> None:
        nonlocal last
        now = time.perf_counter()
        if now - last >= every_s:
            last = now
            print(f"slip: {t:.2f} s of pull, pull {pull:.4g} N, mu_static * sum(N) {cap:.4g} N "
                  f"({now - start:.0f} s)", file=sys.stderr, flush=True)

    return report


#: ranges the rigs take: sizes of centimetres, strains and depths of a material test, times of
#: seconds (each beyond them is a typo that would allocate millions of nodes or run for hours)
LENGTH_RANGE = (1e-4, 0.5)        # m: radius, depth, thickness, width
SPACING_RANGE = (5e-4, 0.05)      # m
MU_RANGE = (0.0, 5.0)
TIME_RANGE = (0.0, 600.0)         # s: the longest pull (relax bounds its own ramp + hold)


def check_args(args) -> None:
    """ConfigError naming any flag outside its range, before a rig is built."""
    from surgsim_envs import validate

    if args.spacing is not None:
        validate.real(args.spacing, "--spacing", lo=SPACING_RANGE[0], hi=SPACING_RANGE[1], unit="m",
                      fix=f"a mesh spacing in [{SPACING_RANGE[0]:g}, {SPACING_RANGE[1]:g}] m, e.g. 0.003")
    lengths = {"indent": ("radius", "depth", "thickness", "width"), "relax": (), "slip": ()}[args.test]
    for key in lengths:
        value = getattr(args, key)
        if value is not None:
            validate.real(value, f"--{key}", lo=LENGTH_RANGE[0], hi=LENGTH_RANGE[1], unit="m",
                          fix=f"a length in [{LENGTH_RANGE[0]:g}, {LENGTH_RANGE[1]:g}] m (SI: 5 mm is 0.005)")
    if args.test == "indent":
        validate.integer(args.points, "--points", lo=2, hi=200, fix="a number of depths, e.g. 12")
    if args.test == "relax":
        validate.real(args.strain, "--strain", lo=0.0, hi=0.5, lo_open=True, fix="a compressive strain in (0, 0.5], e.g. 0.05")
    if args.test == "slip":
        validate.real(args.mu, "--mu", lo=MU_RANGE[0], hi=MU_RANGE[1], fix="a friction coefficient in [0, 5], e.g. 0.6")
        if args.max_pull_time is not None:
            validate.real(args.max_pull_time, "--max-pull-time", lo=TIME_RANGE[0], hi=TIME_RANGE[1], unit="s",
                          lo_open=True, fix=f"seconds in (0, {TIME_RANGE[1]:g}], e.g. 5")


def run(args: argparse.Namespace) -> int:
    from surgsim_envs.bench import material as mt

    check_args(args)
    opts = {}
    if args.integrator:
        opts["integrator"] = args.integrator
    if args.spacing:
        opts["spacing"] = args.spacing
    mat = parse_sets(args.set, args.material or "liver")
    if args.test == "indent":
        from tqdm import tqdm

        with tqdm(total=mt.indent_stages(args.points), desc="material indent", unit="stage", file=sys.stderr,
                  bar_format="{desc}: {n}/{total} |{bar:20}| [{elapsed}] {postfix}") as bar:
            def progress(label):
                bar.set_postfix_str(label, refresh=False)
                bar.update(1)

            res = mt.indent(args.model, mat, indenter_radius=args.radius, depth=args.depth, thickness=args.thickness,
                            width=args.width, bonded=not args.unbonded, n_depths=args.points, progress=progress, **opts)
        out = {"depth": res.depth.tolist(), "force": res.force.tolist(), "nodes": res.nodes,
               "us_per_step": res.us_per_step, "dt": res.dt}
        text = (f"{res.model}/{res.integrator}: {res.nodes} nodes, force {res.force[-1]:.4g} N at depth "
                f"{res.depth[-1] * 1e3:.3g} mm; {res.us_per_step:.4g} us per step at dt {res.dt:.3g} s")
        xy, labels = (res.depth * 1e3, res.force), ("depth (mm)", "force (N)")
    elif args.test == "relax":
        res = mt.relax(args.model, mat, strain=args.strain, ramp_time=args.ramp_time, hold_time=args.hold_time, **opts)
        out = {"time": res.time.tolist(), "force": res.force.tolist()}
        text = (f"{res.model}/{res.integrator}: peak {res.force.max():.4g} N, final {res.force[-1]:.4g} N "
                f"({res.force[-1] / max(res.force.max(), 1e-30):.3f} of peak) after {res.time[-1]:.3g} s")
        xy, labels = (res.time, res.force), ("time (s)", "force (N)")
    else:
        if args.max_pull_time is not None:      # the ramp runs at least PULL_TIME unless told less
            opts["max_pull_time"] = args.max_pull_time
            opts["pull_time"] = min(mt.PULL_TIME, args.max_pull_time)
        res = mt.slip(args.model, mat if (args.set or args.material) else None, mu=args.mu, progress=_slip_progress(), **opts)
        out = {"pull": res.pull.tolist(), "normal_sum": res.normal_sum.tolist(), "slip_onset_pull": res.slip_onset_pull,
               "slip_onset_normal": res.slip_onset_normal, "held_pull": res.held_pull,
               "held_normal": res.held_normal, "normal_start": res.normal_start, "mu": res.mu,
               "mu_static": res.mu_static}
        text = (f"{res.model}: slip onset at pull {res.slip_onset_pull:.4g} N (held {res.held_pull:.4g} N) after "
                f"{res.time[int(np.argmax(res.pull == res.slip_onset_pull))]:.3g} s of pull; mu * sum(N) there = "
                f"{res.mu * res.slip_onset_normal:.4g} N; held / (mu sum N), both at the same instant, "
                f"{res.held_pull / (res.mu * res.held_normal):.3f}; sum(N) before the pull "
                f"{res.normal_start:.4g} N")
        xy, labels = (res.time, res.pull), ("time since pull start (s)", "pull (N)")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(5, 3.5))
        ax.plot(*xy)
        if args.test == "slip":
            ax.plot(res.time, res.mu * res.normal_sum, "--", label="mu * sum(N)")
            ax.legend()
        ax.set_xlabel(labels[0])
        ax.set_ylabel(labels[1])
        fig.tight_layout()
        fig.savefig(args.plot, dpi=120)
        plt.close(fig)
    print(json.dumps(out) if args.json else text)
    return 0
