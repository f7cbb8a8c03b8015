"""``surgsim validate``: signed surface distances of a predicted surface to a reference (Vandewalle et al. 2003, 2.2).

Both surfaces are state files (.npz, format surgsim-state-1: ``positions`` + ``surface``, see
:mod:`surgsim_envs.geometry.state_file`; ``surgsim grow`` writes them) or triangle meshes
(STL/OBJ/PLY/OFF). Writes distance_map.png, histogram.png, validation.json, distances.npz.
"""

from __future__ import annotations

import argparse


def _view(text: str):
    try:
        elev, azim = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--view takes 'elevation,azimuth' in degrees, got {text!r}") from None
    return elev, azim


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--predicted", required=True, help="predicted surface: state .npz or mesh file")
    parser.add_argument("--reference", required=True, help="reference surface (e.g. post-operative): state .npz or mesh")
    parser.add_argument("--out", default="surgsim-out/validate", help="output directory")
    parser.add_argument("--units", default="m", choices=["m", "cm", "mm"], help="units of mesh files (state files: m)")
    parser.add_argument("--range-mm", type=float, default=10.0, help="colour scale +- this many mm (paper: 10)")
    parser.add_argument("--view", type=_view, default=(60.0, -70.0), help="camera 'elevation,azimuth' in degrees")
    parser.add_argument("--title", default="predicted vs reference")


def run(args: argparse.Namespace) -> int:
    from surgsim_envs.planning.validation_report import validation_report
    from surgsim_envs.errors import ConfigError
    from surgsim_envs.geometry.state_file import load_surface_any

    if not (args.range_mm > 0):
        raise ConfigError(f"--range-mm must be > 0, got {args.range_mm}")
    pred = load_surface_any(args.predicted, args.units if not args.predicted.endswith(".npz") else "m")
    ref = load_surface_any(args.reference, args.units if not args.reference.endswith(".npz") else "m")
    s = validation_report(pred, ref, args.out, range_mm=args.range_mm, view=args.view, title=args.title)
    print(f"{s['vertices']} vertices: mu = {s['mu_m'] * 1e3:.3f} mm, sigma = {s['sigma_m'] * 1e3:.3f} mm, "
          f"rms = {s['rms_m'] * 1e3:.3f} mm, range [{s['min_m'] * 1e3:.2f}, {s['max_m'] * 1e3:.2f}] mm, "
          f"{100 * s['within_1mm']:.1f} % within 1 mm")
    print(f"wrote {args.out}/distance_map.png, histogram.png, validation.json, distances.npz")
    return 0
