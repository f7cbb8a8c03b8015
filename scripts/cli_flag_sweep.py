"""Every flag of every ``surgsim`` command with hostile values: each case must be refused with the
command's error (exit 2 and a message) or run; never a traceback, NaN or a silent hang.

    python scripts/cli_flag_sweep.py                       # nan, -1, 1e308, abc on every flag (~25 min)
    python scripts/cli_flag_sweep.py --values nan --only "bench soak"

The flags are read from each command's ``--help``; switches (flags that take no value) are skipped.
Each case runs in this process under an alarm of ``--timeout`` s (tests/fuzz_harness.py) in a
scratch folder: a case still running at the alarm was *accepted* (a valid value starts the
command's real work), listed as ``running`` for a reader to judge (a valid output folder such as
``--out nan`` runs; ``--width 1e308`` running is a missing bound). Prints the counts and every case
that was not refused.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import re
import sys
import tempfile
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

import fuzz_harness as fh  # noqa: E402

from surgsim_envs.cli import main  # noqa: E402
from surgsim_envs.errors import ConfigError  # noqa: E402

COMMANDS = [["models"], ["demo"], ["warmup"], ["material", "indent"], ["material", "relax"], ["material", "slip"],
            ["fit"], ["teleop"], ["run"], ["record"], ["grow"], ["validate"]] + [
    ["bench", b] for b in ("speed loop envs sb3-vec haptics haptics-flood accuracy calibrated-cost stability "
                           "task-accuracy soak diffusion growth memory trajectory layers batch").split()]
#: positional arguments a command needs before its flags
POSITIONAL = {"teleop": ["palpation", "--headless"], "record": ["SurgSim/PalpationPress-v0"],
              "run": [str(ROOT / "tasks" / "palpation_find_inclusion.toml")]}


def quiet_main(argv):
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()) as err:
        try:
            rc = main(argv)
        except SystemExit as exc:
            rc = exc.code
    if rc not in (0, None):
        raise ConfigError(f"exit {rc}: {err.getvalue()[-200:]}")
    return rc


def value_flags(command: list[str]) -> list[str]:
    """The flags of ``command`` that take a value (from its --help: a flag followed by a metavar)."""
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(io.StringIO()):
        try:
            main(command + ["--help"])
        except SystemExit:
            pass
    flags = set()
    for m in re.finditer(r"(--[a-z][a-z0-9-]*)(?:[ =]([A-Z{][A-Za-z0-9_.,{}|-]*))?", buf.getvalue()):
        if m.group(2) and m.group(1) != "--help":
            flags.add(m.group(1))
    return sorted(flags)


def main_sweep(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--values", default="nan,-1,1e308,abc", help="comma-separated hostile values")
    parser.add_argument("--timeout", type=float, default=8.0, help="s before a case counts as accepted and running")
    parser.add_argument("--only", default="", help="only commands whose name contains this text")
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")
    values = args.values.split(",")
    counts = {k: 0 for k in fh.OUTCOMES}
    os.chdir(tempfile.mkdtemp(prefix="surgsim_cli_sweep_"))
    for command in COMMANDS:
        name = " ".join(command)
        if args.only not in name:
            continue
        for flag in value_flags(command):
            for value in values:
                case = command + POSITIONAL.get(command[0], []) + [flag, value]
                if command[0] == "teleop" and flag != "--duration":
                    case += ["--duration", "0.05"]
                kind, detail = fh.outcome(quiet_main, case, timeout_s=args.timeout)
                counts[kind] += 1
                if kind != "refused":
                    label = "running" if kind == "hang" else kind
                    print(f"{label:8s} {' '.join(case)}  {detail[:160] if kind not in ('ok', 'hang') else ''}",
                          flush=True)
    print({("accepted, running at the alarm" if k == "hang" else k): v for k, v in counts.items()})
    return 1 if counts["raw"] or counts["nan"] else 0


if __name__ == "__main__":
    sys.exit(main_sweep())
