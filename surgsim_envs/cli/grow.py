"""``surgsim grow``: predict the skin after a bone distraction with the basic and the growth model.

Runs the synthetic maxillofacial case (:mod:`surgsim_envs.planning.maxillofacial`): basic model
(linear FEM, bone displacement prescribed) and growth model (Vandewalle et al. 2003, k and alpha), writes both
skins as state files (``basic.npz``, ``grown.npz``, format surgsim-state-1; ``surgsim validate``
reads them) and, unless ``--no-reference``, a synthetic reference skin (the growth model at
``--truth-nu/--truth-k`` on a finer mesh; NOT patient data) with the paper's comparison
(colour-coded maps + histograms, ``comparison.png``). ``--sweep`` adds the Fig. 5 sweep.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="surgsim-out/grow", help="output directory")
    parser.add_argument("--spacing", type=float, default=0.004, help="mesh spacing of the prediction (m)")
    parser.add_argument("--nu", type=float, default=0.25, help="Poisson ratio (paper optimum 0.25)")
    parser.add_argument("--k", type=float, default=20.0, help="growth parameter k >= 0 (paper optimum 20)")
    parser.add_argument("--alpha", default="auto", help="stability factor in 1/Pa, or 'auto'")
    parser.add_argument("--tol", type=float, default=1e-5, help="stop when the growth per iteration < tol x the first")
    parser.add_argument("--max-iter", type=int, default=500)
    parser.add_argument("--translation-mm", type=float, default=8.0, help="distraction translation (mm)")
    parser.add_argument("--rotation-deg", type=float, default=8.0, help="distraction rotation (degrees)")
    parser.add_argument("--no-reference", action="store_true", help="skip the synthetic reference and the comparison")
    parser.add_argument("--reference-spacing", type=float, default=0.0025, help="mesh spacing of the synthetic reference (m)")
    parser.add_argument("--truth-nu", type=float, default=0.35, help="nu of the synthetic reference")
    parser.add_argument("--truth-k", type=float, default=12.0, help="k of the synthetic reference")
    parser.add_argument("--sweep", action="store_true", help="also run the Fig. 5 sweep over nu and k (minutes)")


def run(args: argparse.Namespace) -> int:
    import numpy as np
    from tqdm import tqdm

    from surgsim_envs.planning.validation_report import comparison_figure
    from surgsim_envs.geometry.state_file import save_state
    from surgsim_envs.geometry.surface_error import surface_error
    from surgsim_envs.planning.maxillofacial import DistractionCase
    from surgsim_envs.planning.sweep import grown_skin, plot_sweep, sweep
    from surgsim_envs.tissue.growth import GrowthSolver, mesh_volume

    alpha = args.alpha if args.alpha == "auto" else _float(args.alpha, "--alpha")
    check_args(args)
    case = DistractionCase(translation=args.translation_mm * 1e-3, rotation_deg=args.rotation_deg)
    os.makedirs(args.out, exist_ok=True)
    model = case.model(args.spacing, args.nu)
    solver = GrowthSolver.from_model(model)
    with tqdm(total=args.max_iter, desc="growth iterations", unit="it", file=sys.stderr) as bar:
        res = solver.grow(args.k, alpha, tol=args.tol, max_iter=args.max_iter, callback=lambda it, g: bar.update())
    skin = case.skin_faces(model.volume)
    meta = dict(case="maxillofacial", nu=args.nu, k=args.k, alpha=res.alpha, spacing=args.spacing)
    save_state(os.path.join(args.out, "basic.npz"), res.basic_positions, skin, model.rest_positions, model="basic", **meta)
    save_state(os.path.join(args.out, "grown.npz"), res.positions, skin, model.rest_positions, model="growth", **meta)
    v0 = mesh_volume(model.rest_positions, model.tets)
    summary = {"nodes": model.n_nodes, "iterations": res.iterations, "alpha": res.alpha, "k": args.k, "nu": args.nu,
               "factor_s": res.factor_seconds, "grow_s": res.iterate_seconds,
               "volume_ratio_basic": mesh_volume(res.basic_positions, model.tets) / v0,
               "volume_ratio_grown": mesh_volume(res.positions, model.tets) / v0}
    print(f"{model.n_nodes} nodes: growth converged in {res.iterations} iterations (alpha = {res.alpha:.4g} 1/Pa), "
          f"volume x{summary['volume_ratio_basic']:.4f} basic, x{summary['volume_ratio_grown']:.4f} grown")
    if not args.no_reference:
        ref = grown_skin(case, args.reference_spacing, args.truth_nu, args.truth_k)
        save_state(os.path.join(args.out, "reference.npz"), ref[0], ref[1], model="synthetic reference",
                   nu=args.truth_nu, k=args.truth_k, spacing=args.reference_spacing)
        entries = []
        for label, pos in (("basic model", res.basic_positions), (f"growth model (k = {args.k:g})", res.positions)):
            err = surface_error(pos, skin, ref[0], ref[1])
            entries.append((label, pos, skin, err))
            summary[label] = err.summary()
            print(f"{label:<24} vs synthetic reference: mu = {err.mean * 1e3:+.2f} mm, sigma = {err.std * 1e3:.2f} mm")
        comparison_figure(os.path.join(args.out, "comparison.png"), entries, suptitle=(
            f"Skin error vs a SYNTHETIC reference (growth model nu = {args.truth_nu:g}, k = {args.truth_k:g}, "
            f"{args.reference_spacing * 1e3:g} mm mesh); prediction nu = {args.nu:g} on {args.spacing * 1e3:g} mm"))
        if args.sweep:
            result = sweep(case, truth=(args.truth_nu, args.truth_k), spacing=args.spacing,
                           reference_spacing=args.reference_spacing, reference=ref)
            plot_sweep(result, os.path.join(args.out, "sweep.png"))
            summary["sweep"] = result.to_dict()
            print(f"sweep minimum at (nu, k) = {result.recovered()}, truth {(args.truth_nu, args.truth_k)}")
    with open(os.path.join(args.out, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=1)
    print(f"wrote {args.out}/ basic.npz grown.npz" + ("" if args.no_reference else " reference.npz comparison.png")
          + (" sweep.png" if args.sweep else "") + " summary.json")
    return 0


#: m, the mesh spacings the synthetic case takes: finer than 1.5 mm is a sparse LU of millions of
#: dofs (hours), coarser than 2 cm leaves the face a few elements thick (no skin left to compare)
SPACING_RANGE = (0.0015, 0.02)
#: |distraction| the case takes: the paper's distractions are several mm and degrees; beyond these
#: the prescribed bone move inverts the linear (small-strain) mesh
MAX_TRANSLATION_MM, MAX_ROTATION_DEG = 30.0, 30.0


def check_args(args) -> None:
    """ConfigError naming any flag outside the range the case can take, before anything runs."""
    from surgsim_envs import validate

    for flag, value in (("--spacing", args.spacing), ("--reference-spacing", args.reference_spacing)):
        validate.real(value, flag, lo=SPACING_RANGE[0], hi=SPACING_RANGE[1], unit="m",
                      fix=f"a mesh spacing in [{SPACING_RANGE[0]:g}, {SPACING_RANGE[1]:g}] m, e.g. 0.004")
    for flag, value in (("--nu", args.nu), ("--truth-nu", args.truth_nu)):
        validate.real(value, flag, lo=0.0, hi=0.499, fix="a Poisson ratio in [0, 0.499], e.g. 0.25")
    for flag, value in (("--k", args.k), ("--truth-k", args.truth_k)):
        validate.real(value, flag, lo=0.0, hi=1e4, fix="the growth parameter k in [0, 1e4], e.g. 20")
    validate.real(args.tol, "--tol", lo=0.0, hi=1.0, lo_open=True, hi_open=True,
                  fix="a relative growth per iteration in (0, 1), e.g. 1e-5")
    validate.integer(args.max_iter, "--max-iter", lo=1, hi=100_000, fix="iterations, e.g. 500")
    validate.real(args.translation_mm, "--translation-mm", lo=-MAX_TRANSLATION_MM, hi=MAX_TRANSLATION_MM, unit="mm",
                  fix=f"a distraction translation within +-{MAX_TRANSLATION_MM:g} mm, e.g. 8")
    validate.real(args.rotation_deg, "--rotation-deg", lo=-MAX_ROTATION_DEG, hi=MAX_ROTATION_DEG, unit="deg",
                  fix=f"a distraction rotation within +-{MAX_ROTATION_DEG:g} degrees, e.g. 8")


def _float(text, name):
    from surgsim_envs.errors import ConfigError

    try:
        value = float(text)
    except ValueError:
        raise ConfigError(f"{name} must be a number (1/Pa) or 'auto', got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise ConfigError(f"{name}={text!r} must be a positive finite number (1/Pa) or 'auto'")
    return value
