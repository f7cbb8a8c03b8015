"""``surgsim bench speed``: tissue-model step time per model, integrator and node count.

For every registered model (models that fail to import are skipped with a note on stderr), each of
its integrators and each requested node count, a box of liver (5 mm lattice, shape chosen to hit
the count) is clamped at its bottom face and pressed on its top face with 0.5 N (so implicit
solvers do real work). After a warm-up (which also compiles numba kernels) the steps of each
repeat are timed; the row reports the median microseconds per step over the repeats.
dt is 1 ms, or the model's stable dt (DT_SAFETY x its critical dt at rest) for explicit
integrators if that is smaller. Every row names the dt it ran at (``dt_s``). The critical dt of a
loaded body can fall below its rest value (mass-spring at 245 nodes: 0.943 ms under the load
against more than 1.25 ms at rest), so an explicit case that diverges is re-run from scratch at
DT_SAFETY x the critical dt the guard reported (at most :data:`RETRIES` times); the row then says
so in ``note``. A case that still fails keeps ``us_per_step: null`` and says why in ``error``.
``--relax-ratio`` times instead each model with the liver preset against the same with
relax_fraction 0, alternately in one process (bench/relax_cost.py).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from typing import Any

import numpy as np

from surgsim_envs import validate
from surgsim_envs.bench.material import is_explicit
from surgsim_envs.bench.speed_volume import bench_volume, top_load as _load
from surgsim_envs.errors import ConfigError

DEFAULT_SIZES = (250, 1000, 4000)


#: the largest --steps / --repeats / --warmup: one case of 10^6 steps of 4,000 nodes is minutes
MAX_STEPS = 1_000_000


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if not 0 < value <= MAX_STEPS:
        raise argparse.ArgumentTypeError(f"expected a positive integer of at most {MAX_STEPS:,} (each case is timed "
                                         f"that many times), got {value}")
    return value


def parse_sizes(text: str) -> list[int]:
    """'250,1000,4000' -> [250, 1000, 4000]; ConfigError on anything else."""
    try:
        sizes = [int(s) for s in str(text).split(",") if s.strip()]
    except ValueError:
        raise ConfigError(f"--sizes must be comma-separated node counts like 250,1000,4000, got {text!r}") from None
    if not sizes or any(s < 8 for s in sizes):
        raise ConfigError(f"--sizes needs node counts >= 8, got {text!r}")
    return sizes


RETRIES = 2


def time_model(cls, integrator: str, target: int, repeats: int, steps: int, warmup: int,
               dt: float = 1e-3) -> dict[str, Any]:
    """One benchmark row {"model", "integrator", "nodes", "dt_s", "us_per_step"} plus "note" when
    the dt was lowered after a divergence and "error" (with us_per_step None) when the case failed;
    the reason also goes to stderr."""
    from surgsim_envs.errors import TissueUnstableError
    from surgsim_envs.tissue.base import DT_SAFETY

    vol = bench_volume(target)
    z = vol.nodes[:, 2]
    bottom, top = np.isclose(z, z.min()), np.isclose(z, z.max())
    row: dict[str, Any] = {"model": cls.name, "integrator": integrator, "nodes": int(vol.n_nodes),
                           "dt_s": None, "us_per_step": None}
    requested = dt
    for attempt in range(RETRIES + 1):
        try:
            model = cls(vol, "liver", integrator=integrator, fixed=bottom)
            if attempt == 0 and is_explicit(cls, integrator):
                limit = model.stable_dt()            # the one safety factor (tissue/base.py DT_SAFETY)
                if math.isfinite(limit):
                    dt = min(dt, limit)
            row["dt_s"] = dt
            times = _time_steps(model, dt, _load(model, top), repeats, steps, warmup)
            break
        except TissueUnstableError as exc:
            lower = DT_SAFETY * exc.critical_dt
            if (attempt < RETRIES and is_explicit(cls, integrator) and math.isfinite(lower)
                    and 0.0 < lower < dt):
                row["note"] = (f"unstable at dt {dt * 1e3:.4g} ms under the load (critical dt "
                               f"{exc.critical_dt * 1e3:.4g} ms); ran at {lower * 1e3:.4g} ms = "
                               f"{DT_SAFETY} x critical, the largest stable dt below {requested * 1e3:.4g} ms")
                dt = lower
                continue
            return _failed(row, cls, integrator, vol, "unstable", exc)
        except Exception as exc:  # a model under construction: report, keep benchmarking the others
            return _failed(row, cls, integrator, vol, type(exc).__name__, exc)
    if "note" in row:
        print(f"surgsim bench speed: {cls.name}/{integrator} at {vol.n_nodes} nodes: {row['note']}", file=sys.stderr)
    row["us_per_step"] = round(statistics.median(times), 2)
    return row


def _time_steps(model, dt: float, forces, repeats: int, steps: int, warmup: int) -> list[float]:
    for _ in range(warmup):
        model.step(dt, forces)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(steps):
            model.step(dt, forces)
        times.append((time.perf_counter() - t0) / steps * 1e6)
    return times


def _failed(row: dict, cls, integrator: str, vol, kind: str, exc: Exception) -> dict:
    first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    row["us_per_step"] = None
    row["error"] = f"{kind}: {first[:300]}"
    print(f"surgsim bench speed: {cls.name}/{integrator} at {vol.n_nodes} nodes failed ({kind}): {first[:300]}",
          file=sys.stderr)
    return row


def available_models() -> list[tuple[str, Any]]:
    """(name, class) of every registered model that imports; failures are reported on stderr."""
    from surgsim_envs.tissue import registry

    out = []
    for name in registry.names():
        try:
            out.append((name, registry.get(name)))
        except Exception as exc:  # a model being written elsewhere must not stop the benchmark
            print(f"surgsim bench speed: skipping model {name!r} ({type(exc).__name__}: {exc})", file=sys.stderr)
    return out


def run_bench(sizes, repeats: int = 5, steps: int = 50, warmup: int = 20, models=None, progress: bool = True) -> list[dict]:
    """Rows for every (model, integrator, size); ``models`` restricts to those names."""
    from tqdm import tqdm

    classes = [(n, c) for n, c in available_models() if models is None or n in models]
    jobs = [(c, integ, size) for _, c in classes for integ in c.integrators for size in sizes]
    rows = []
    with tqdm(jobs, desc="bench speed", unit="case", file=sys.stderr, disable=not progress) as bar:
        for cls, integ, size in bar:
            bar.set_postfix_str(f"{cls.name}/{integ}/{size}")
            rows.append(time_model(cls, integ, size, repeats, steps, warmup))
    return rows


def format_table(rows: list[dict]) -> str:
    header = f"{'model':<14} {'integrator':<12} {'nodes':>7} {'dt ms':>8} {'us/step':>10}"
    lines = [header, "-" * len(header)]
    notes = []
    for r in rows:
        us = "failed" if r["us_per_step"] is None else f"{r['us_per_step']:.1f}"
        dt = "-" if r.get("dt_s") is None else f"{r['dt_s'] * 1e3:.4g}"
        mark = ""
        if r.get("note") or r.get("error"):
            notes.append(f"[{len(notes) + 1}] {r['model']}/{r['integrator']}/{r['nodes']}: {r.get('error') or r['note']}")
            mark = f" [{len(notes)}]"
        lines.append(f"{r['model']:<14} {r['integrator']:<12} {r['nodes']:>7} {dt:>8} {us:>10}{mark}")
    return "\n".join(lines + notes)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print a JSON list of rows {model, integrator, nodes, dt_s, us_per_step} "
                             "(+ note when dt was lowered, error when a case failed)")
    parser.add_argument("--repeats", type=_positive_int, default=5, help="timed repeats per case (median reported); default 5")
    parser.add_argument("--steps", type=_positive_int, default=50, help="steps per timed repeat; default 50")
    parser.add_argument("--warmup", type=_positive_int, default=20, help="untimed steps first (numba compile); default 20")
    parser.add_argument("--sizes", default=",".join(map(str, DEFAULT_SIZES)),
                        help="comma-separated target node counts; default 250,1000,4000")
    parser.add_argument("--models", default=None, help="comma-separated model names (default: all registered)")
    parser.add_argument("--relax-ratio", action="store_true",
                        help="instead: each model (default fem, mass_spring, mass_spring_calibrated) with the liver "
                             "preset (relax_fraction 0.5) against relax_fraction 0, stepped alternately in one "
                             "process (bench/relax_cost.py)")


def run(args: argparse.Namespace) -> int:
    sizes = parse_sizes(args.sizes)
    models = validate.name_list(args.models, "--models", [n for n, _ in available_models()])
    if getattr(args, "relax_ratio", False):
        from surgsim_envs.bench import relax_cost

        names = models or list(relax_cost.DEFAULT_MODELS)
        classes = [c for n, c in available_models() if n in names]
        rows = [relax_cost.relax_row(c, integ, size, args.repeats, args.steps, args.warmup)
                for c in classes for integ in c.integrators for size in sizes]
        print(json.dumps(rows, indent=2) if args.json else relax_cost.format_rows(rows))
        return 0
    rows = run_bench(sizes, repeats=args.repeats, steps=args.steps, warmup=args.warmup, models=models)
    print(json.dumps(rows, indent=2) if args.json else format_table(rows))
    return 0
