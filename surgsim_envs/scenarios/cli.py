"""``surgsim run SCENARIO.toml``: run a trainee scenario and write its report.

    surgsim run tasks/grasp_slippage_mu_sweep.toml --out out/mu --no-video
    surgsim run tasks/spleen_grasp_and_retract.toml --device scripted      # a simulated hand drives
    surgsim run tasks/palpation_find_inclusion.toml --device replay:hand.csv
    surgsim run tasks/palpation_policy.toml --policy my_pkg.policies:scan
    surgsim run tasks/palpation_find_inclusion.toml --duration-scale 0.25 --viewer

The file is validated before anything is simulated (errors name the key, its value and the
line). Writes ``report.json``, ``forces.png``, ``report.md``, ``timeseries.npz`` and (unless
``--no-video`` or without OpenGL) ``video.mp4`` into ``--out`` (default
``surgsim-out/<scenario name>``) and prints the score.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

from surgsim_envs.errors import ConfigError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", help="scenario file (.toml), e.g. tasks/spleen_grasp_and_retract.toml")
    parser.add_argument("--out", default=None, help="output directory (default surgsim-out/<scenario name>)")
    parser.add_argument("--device", default=None,
                        help="drive every phase with a device: scripted | replay:FILE | keyboard | udp:PORT")
    parser.add_argument("--policy", default=None, help="drive with a policy: 'module:function' or an SB3 .zip")
    parser.add_argument("--duration-scale", type=float, default=1.0,
                        help="multiply every phase duration (e.g. 0.25 for a quick run; default 1)")
    parser.add_argument("--tremor", type=float, default=0.0,
                        help="m, tremor amplitude of the default simulated hand (--device scripted)")
    parser.add_argument("--no-video", action="store_true", help="do not render video.mp4")
    parser.add_argument("--viewer", action="store_true", help="show the interactive MuJoCo viewer (needs a display)")
    parser.add_argument("--check", action="store_true", help="only validate the file, run nothing")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args) -> int:
    from surgsim_envs.scenarios.schema import load_scenario

    sc = load_scenario(args.scenario)
    scale = args.duration_scale
    if not (isinstance(scale, float) and math.isfinite(scale) and 0 < scale <= 100):
        raise ConfigError(f"--duration-scale {scale!r} must be in (0, 100]")
    if not (math.isfinite(args.tremor) and args.tremor >= 0):
        raise ConfigError(f"--tremor {args.tremor!r} must be >= 0 m")
    if args.check:
        runs = len(sc.runs())
        print(f"{args.scenario}: valid scenario '{sc.name}' ({len(sc.phases)} phases, {runs} run{'s' * (runs != 1)})")
        return 0
    if args.viewer and not os.environ.get("DISPLAY") and sys.platform.startswith("linux"):
        print("surgsim run: --viewer needs a display ($DISPLAY is not set); run without --viewer", file=sys.stderr)
        return 2
    if args.device and args.device.startswith("keyboard") and not args.viewer:
        raise ConfigError("--device keyboard needs --viewer (the keys are read from the viewer window)")
    from surgsim_envs.scenarios.report import write_report
    from surgsim_envs.scenarios.runner import run_scenario

    out = Path(args.out) if args.out else Path("surgsim-out") / sc.name
    out.mkdir(parents=True, exist_ok=True)
    results = run_scenario(sc, duration_scale=scale, device=args.device, policy=args.policy, out_dir=out,
                           video=not args.no_video, viewer=args.viewer, progress=not args.quiet, tremor=args.tremor)
    report = write_report(results, out)
    print(f"surgsim run: {sc.name}: score {report['score']:.1f} / 100, "
          f"{'passed' if report['passed'] else 'not passed'}")
    for name, c in report["criteria"].items():
        value = "-" if c["value"] is None else f"{c['value']:.4g}{' ' + c['unit'] if c['unit'] else ''}"
        print(f"  {name:<18} {value:<14} score {c['score']:.2f} {'ok' if c['passed'] else 'FAILED'}")
    if len(report["runs"]) > 1:
        for r in report["runs"]:
            keys = ", ".join(f"{k}={r[k]}" for k in sc.sweep)
            onset = "no slip" if r["slip_onset_pull"] is None else f"slip onset at {r['slip_onset_pull']:.3f} N pull"
            print(f"  run {keys}: peak normal {r['peak_normal']:.3f} N, {onset}, score {r['score']:.1f}")
    for r in report["runs"]:
        if r["error"]:
            print(f"  run stopped early: {r['error']}", file=sys.stderr)
    print(f"  wrote {', '.join(str(v) for v in report['files'].values())}")
    return 0
