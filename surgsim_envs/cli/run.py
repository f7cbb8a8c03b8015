"""``surgsim run SCENARIO.toml``: run a trainee scenario and write its report.

    surgsim run tasks/grasp_slippage_mu_sweep.toml --out out/mu --no-video
    surgsim run tasks/spleen_grasp_and_retract.toml --device scripted      # a simulated hand drives
    surgsim run tasks/palpation_find_inclusion.toml --device replay:hand.csv
    surgsim run tasks/palpation_policy.toml --policy scan.npz                 # a data policy
    surgsim run tasks/palpation_policy.toml --policy my_pkg.policies:scan --allow-code
    surgsim run tasks/palpation_find_inclusion.toml --duration-scale 0.25 --viewer

The file is validated before anything is simulated (errors name the key, its value and the
line). Writes ``report.json``, ``forces.png``, ``report.md``, ``timeseries.npz`` and (unless
``--no-video`` or without OpenGL) ``video.mp4`` into ``--out`` (default
``surgsim-out/<scenario name>``) and prints the score.

Several files run one after the other (``surgsim run tasks/*.toml``): one report each (in
``--out/<scenario name>`` when ``--out`` is given), then a summary table; the exit status is 2 if
any file failed.

Paths: a path typed on the command line (``--policy FILE``, ``--device replay:FILE``, ``--out``)
is taken from the working directory, as in any shell command; a relative path written *inside* a
scenario file (its ``[policy] file``, ``replay:FILE``, ``trainee.script``, an organ mesh) is
taken from the scenario file's own folder first, so a scenario folder can be moved or shared as a
whole.

Trust model: a scenario file is data. Policies that load code (``file.py:function``,
``module:function``, pickled stable-baselines3 ``.zip``) are refused unless ``--allow-code`` is
given; even then a scenario file may only load ``.py``/``.zip`` files from its own folder (a
``--policy`` typed on the command line may name any module or file). ``.npz`` data policies and
``builtin:NAME`` policies need no flag.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
from pathlib import Path

from surgsim_envs.errors import ConfigError
from surgsim_envs.haptics.device_kinds import device_kind


def device_specs(sc, override: str | None) -> list[str]:
    """The device specs a run of ``sc`` opens: ``override`` (``--device``) for every phase, else
    the device of each phase driven by one."""
    if override is not None:
        return [override]
    specs = [p.device for p in sc.phases if p.driver == "device"]
    if sc.trainee.driver == "device":
        specs.append(sc.trainee.device)
    return sorted(set(specs))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", nargs="+",
                        help="scenario file(s) (.toml), e.g. tasks/spleen_grasp_and_retract.toml or tasks/*.toml")
    parser.add_argument("--out", default=None,
                        help="output directory (default surgsim-out/<scenario name>; with several scenarios "
                             "OUT/<scenario name>); taken from the working directory")
    parser.add_argument("--device", default=None,
                        help="drive every phase with a device: scripted | replay:FILE | keyboard | udp:PORT "
                             "(FILE is taken from the working directory)")
    parser.add_argument("--policy", default=None,
                        help="drive with a policy: a .npz data policy, builtin:NAME, or (with --allow-code) "
                             "'module:function', 'file.py:function' or an SB3 .zip; a file is taken from the "
                             "working directory")
    parser.add_argument("--allow-code", action="store_true",
                        help="allow policies that load and run Python code (from the scenario's folder, or named "
                             "by --policy); off by default: sharing a scenario must not share a program")
    parser.add_argument("--duration-scale", type=float, default=1.0,
                        help="multiply every phase duration (e.g. 0.25 for a quick run; default 1)")
    parser.add_argument("--tremor", type=float, default=0.0,
                        help="m, tremor amplitude of the default simulated hand (--device scripted)")
    parser.add_argument("--no-video", action="store_true", help="do not render video.mp4")
    parser.add_argument("--viewer", action="store_true", help="show the interactive MuJoCo viewer (needs a display)")
    parser.add_argument("--check", action="store_true", help="only validate the file, run nothing")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def command_line_path(ref: str | None) -> str | None:
    """A ``--policy`` or ``--device`` value with its file part made absolute from the working
    directory (the scenario's folder is for paths written inside the scenario file). Module
    references (``pkg.mod:function``), ``builtin:``/``shipped:`` names and device kinds without a
    file pass unchanged."""
    if ref is None:
        return None
    from surgsim_envs.scenarios.policies import policy_kind

    if ref.startswith("replay:"):
        file = ref[len("replay:"):]
        return ref if not file or Path(file).is_absolute() else "replay:" + str(Path.cwd() / file)
    if ref.endswith((".npz", ".zip")):
        return ref if Path(ref).is_absolute() else str(Path.cwd() / ref)
    try:
        kind = policy_kind(ref)
    except ConfigError:
        return ref                          # not a policy reference: let the validation name it
    file, _, attr = ref.rpartition(":")
    if kind == "code" and file.endswith(".py") and not Path(file).is_absolute():
        return f"{Path.cwd() / file}:{attr}"
    return ref


def run(args) -> int:
    paths = list(args.scenario) if isinstance(args.scenario, (list, tuple)) else [args.scenario]
    if len(paths) == 1:
        return run_one(args, paths[0], Path(args.out) if args.out else None)
    from surgsim_envs.errors import SurgSimError

    rows = []
    for path in paths:
        print(f"surgsim run: {path}")
        try:
            rc = run_one(args, path, Path(args.out) if args.out else None, summary=rows)
            if rc != 0:
                rows.append((path, None, f"exit status {rc}"))
        except SurgSimError as exc:
            print(f"surgsim run: {path}: error: {exc}", file=sys.stderr)
            rows.append((path, None, str(exc).splitlines()[0][:120]))
    print(format_summary(rows))
    return 0 if all(r[1] is not None for r in rows) else 2


def format_summary(rows) -> str:
    """The table after several scenarios: (file, report or None, error or None) per row."""
    ok = sum(r[1] is not None for r in rows)
    lines = [f"surgsim run: {len(rows)} scenarios, {ok} ran, {len(rows) - ok} failed"]
    for path, report, error in rows:
        if report is None:
            lines.append(f"  {str(path):<44} error: {error}")
        elif report.get("checked_only"):
            lines.append(f"  {str(path):<44} valid")
        else:
            lines.append(f"  {str(path):<44} score {report['score']:5.1f} / 100  "
                         f"{'passed' if report['passed'] else 'not passed'}")
    return "\n".join(lines)


def run_one(args, scenario: str, out: Path | None, summary: list | None = None) -> int:
    """Run one scenario file into ``out`` (None: surgsim-out/<scenario name>). With ``summary``
    (a list; several files) the output goes to ``out/<scenario name>`` and (file, report, None)
    is appended to it."""
    from surgsim_envs.scenarios.loader import load_scenario

    from surgsim_envs.scenarios.policies import check_policy_reference
    from surgsim_envs.scenarios.schema import LIMITS, NAME_PATTERN

    allow_code = bool(getattr(args, "allow_code", False))
    sc = load_scenario(scenario, allow_code=allow_code)
    policy, device = args.policy, args.device      # validated as typed (from the working directory) ...
    scale = args.duration_scale
    if not (isinstance(scale, float) and math.isfinite(scale) and 0 < scale <= 100):
        raise ConfigError(f"--duration-scale {scale!r} must be in (0, 100]")
    sc.scaled(scale)  # raises when the scaled run exceeds the simulated-time limit
    tremor_max = LIMITS["trainee.tremor"][1]
    if not (math.isfinite(args.tremor) and 0 <= args.tremor <= tremor_max):
        raise ConfigError(f"--tremor {args.tremor!r} must be in [0, {tremor_max}] m")
    if policy is not None:
        check_policy_reference(policy, None, allow_code=allow_code, trusted=True)
    if device is not None:
        from surgsim_envs.scenarios.schema import KeyLocator, ValidationContext, validate_driver

        validate_driver(ValidationContext("command line", KeyLocator(None)), ("--device",), "device", device, "",
                        folder=None, check_files=True)
    if not args.viewer:   # a device read from the viewer window cannot run without it (--check says so too)
        for spec in device_specs(sc, device):
            if device_kind(spec)[0].needs_viewer:
                raise ConfigError(f"device {spec!r} reads its input from the viewer window: run with --viewer (and a "
                                  "display), or use a scripted or replay device")
    if args.check:
        runs = len(sc.runs())
        if summary is not None:
            summary.append((scenario, {"checked_only": True}, None))
        print(f"{scenario}: valid scenario '{sc.name}' ({len(sc.phases)} phases, {runs} run{'s' * (runs != 1)})")
        return 0
    if args.viewer and not os.environ.get("DISPLAY") and sys.platform.startswith("linux"):
        print("surgsim run: --viewer needs a display ($DISPLAY is not set); run without --viewer", file=sys.stderr)
        return 2
    from surgsim_envs.scenarios.report import number_text as _num, write_report
    from surgsim_envs.scenarios.runner import run_scenario

    policy, device = command_line_path(policy), command_line_path(device)   # ... and run from there

    if out is None or summary is not None:
        if not re.fullmatch(NAME_PATTERN, sc.name):  # also checked by the schema: never leave surgsim-out/
            raise ConfigError(f"scenario name {sc.name!r} cannot name an output folder; pass --out DIR")
        out = (Path("surgsim-out") if out is None else out) / sc.name
    out.mkdir(parents=True, exist_ok=True)
    results = run_scenario(sc, duration_scale=scale, device=device, policy=policy, out_dir=out,
                           video=not args.no_video, viewer=args.viewer, progress=not args.quiet, tremor=args.tremor)
    report = write_report(results, out)
    print(f"surgsim run: {sc.name}: score {_num(report['score'], '.1f')} / 100, "
          f"{'passed' if report['passed'] else 'not passed'}")
    for name, c in report["criteria"].items():
        value = "-" if c["value"] is None else f"{c['value']:.4g}{' ' + c['unit'] if c['unit'] else ''}"
        print(f"  {name:<18} {value:<14} score {_num(c['score'], '.2f')} {'ok' if c['passed'] else 'FAILED'}")
    if len(report["runs"]) > 1:
        for r in report["runs"]:
            keys = ", ".join(f"{k}={r[k]}" for k in sc.sweep)
            onset = "no slip" if r["slip_onset_pull"] is None else f"slip onset at {r['slip_onset_pull']:.3f} N pull"
            print(f"  run {keys}: peak normal {r['peak_normal']:.3f} N, {onset}, score {_num(r['score'], '.1f')}")
    for r in report["runs"]:
        if r["error"]:
            print(f"  run stopped early: {r['error']}", file=sys.stderr)
    print(f"  wrote {', '.join(str(v) for v in report['files'].values())}")
    if summary is not None:
        summary.append((scenario, report, None))
    return 0
