"""The counts table of the hostile-input fuzz suites: per surface, how many drawn cases worked,
were refused with the project's error, raised a raw exception, gave NaN or hung.

    python scripts/fuzz_counts.py               # 300 cases per surface (a few minutes)
    python scripts/fuzz_counts.py --cases 50    # quicker
    python scripts/fuzz_counts.py --only udp    # one surface

The surfaces and strategies are those of tests/test_fuzz_*.py (tests/fuzz_surfaces.py), drawn
afresh by hypothesis on every run (no example database), each case under a per-case timeout
(tests/fuzz_harness.py). Prints a Markdown table and the first distinct failure per surface.
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from hypothesis import HealthCheck, given, settings  # noqa: E402

import fuzz_harness as fh  # noqa: E402
import fuzz_surfaces as fs  # noqa: E402


def _task_envs() -> dict:
    """One env per task whose actions are fuzzed, keyed by the short task name."""
    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401

    envs = {}
    for task in fs.ACTION_TASKS:
        envs[task] = gym.make(f"SurgSim/{task}")
        envs[task].reset(seed=0)
    return envs


def surfaces(envs: dict):
    env = envs["Palpation-v0"]
    return {
        "task config fields (5 tasks)": (fs.config_case(), fs.run_config),
        "reset options (Palpation-v0)": (fs.reset_case(), lambda c: fs.run_reset(env, c)),
        "actions (5 tasks)": (fs.task_action_case(), lambda c: fs.run_task_action(envs, c)),
        "vector env options and actions": (fs.vector_case(), fs.run_vector),
        "`surgsim teleop` flags": (fs.cli_case(), fs.run_teleop_flags),
        "`surgsim bench growth` flags": (fs.growth_case(), fs.run_growth_flags),
        "scenario values (env_kwargs, criteria)": (fs.scenario_case(), fs.run_scenario_check),
        "`.npz` policy files": (fs.npz_case(), fs.run_npz),
        "mesh files (VTK tets, STL/OBJ/PLY/OFF surfaces)": (fs.mesh_case(), fs.run_mesh),
        "UDP pose datagrams (keyed and not)": (fs.udp_case(), fs.run_udp),
    }


def count(strategy, run, cases: int, timeout_s: float):
    counts, failures = collections.Counter(), {}

    @settings(max_examples=cases, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(strategy)
    def one(case):
        kind, detail = fh.outcome(run, case, timeout_s=timeout_s)
        counts[kind] += 1
        if kind not in ("ok", "refused"):
            failures.setdefault(detail[:80], (kind, case, detail[:300]))

    one()
    return counts, failures


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=300, help="cases per surface (default 300)")
    parser.add_argument("--timeout", type=float, default=30.0, help="s per case before it counts as a hang")
    parser.add_argument("--only", default="", help="run only the surfaces whose name contains this text")
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")
    envs = _task_envs()
    rows, problems = [], []
    total = collections.Counter()
    t0 = time.perf_counter()
    for name, (strategy, run) in surfaces(envs).items():
        if args.only.lower() not in name.lower():
            continue
        counts, failures = count(strategy, run, args.cases, args.timeout)
        total.update(counts)
        rows.append((name, counts))
        problems += [(name, *f) for f in failures.values()]
        print(f"{name}: {dict(counts)}", file=sys.stderr, flush=True)
    for env in envs.values():
        env.close()
    print("| surface | cases | ok | refused with error | raw exception | NaN | hang |")
    print("|---|---|---|---|---|---|---|")
    for name, c in rows + [("**total**", total)]:
        print(f"| {name} | {sum(c.values())} | {c['ok']} | {c['refused']} | {c['raw']} | {c['nan']} | {c['hang']} |")
    print(f"\n{time.perf_counter() - t0:.0f} s")
    for name, kind, case, detail in problems:
        print(f"- {name}: {kind}: {case!r:.200} -> {detail}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
