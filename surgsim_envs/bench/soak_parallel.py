"""``surgsim bench soak --workers N --out FILE.json [--resume]``: a soak split across processes
that keeps what it counted when interrupted.

    surgsim bench soak --task all --steps 1000000 --workers 2 --out soak.json
    surgsim bench soak --task all --steps 1000000 --workers 2 --out soak.json --resume   # after ^C

Per task the requested steps are split into *segments*, one per worker process (sizes differ
by at most one step). Every segment runs :func:`~surgsim_envs.bench.soak.soak` with its own
seed, ``SeedSequence([seed, k])`` for segment number ``k`` (0, 1, 2, ... over the whole history
of the task in ``FILE``, so a resumed run never repeats a seed). A worker writes its row so far
to ``FILE.parts/<task>-<seed>.json`` every ``--checkpoint-every`` steps and at its end; the
parent merges the part files into ``FILE`` (atomically, ``os.replace``) when the task ends or is
interrupted, then removes them. ``--resume`` reads ``FILE`` and any part files a killed run
left, and runs only the steps still missing, in new segments.

``FILE`` holds, per task, every segment's row (each with its own RSS figures: memory is per
process) and their merge (:func:`merge_rows`): counts and steps summed, exception types summed,
the largest peak force, the largest RSS growth and slope of any segment, and ``complete`` (the
requested steps all ran). The docs table is made from the merged rows.
"""

from __future__ import annotations

import json
import math
import multiprocessing as mp
import os
import re
import sys
import time
from pathlib import Path

import numpy as np

from surgsim_envs.errors import ConfigError

#: per-segment counts that add up
SUMMED = ("steps", "episodes", "nan", "exceptions", "unstable", "obs_out_of_space", "force_out_of_bounds")


def split_steps(total: int, workers: int) -> list[int]:
    """``total`` steps over ``workers`` segments, sizes differing by at most one, no empty one."""
    if isinstance(total, bool) or not isinstance(total, int) or total < 0:
        raise ConfigError(f"steps must be an integer >= 0, got {total!r}")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ConfigError(f"--workers must be an integer >= 1, got {workers!r}")
    base, extra = divmod(total, workers)
    return [base + (1 if k < extra else 0) for k in range(workers) if base + (1 if k < extra else 0) > 0]


def segment_seed(seed: int, k: int) -> int:
    """The seed of segment ``k`` of a soak with master seed ``seed`` (distinct for distinct k)."""
    return int(np.random.SeedSequence([int(seed), int(k)]).generate_state(1, dtype=np.uint32)[0])


def merge_rows(task: str, rows: list[dict], steps_requested: int) -> dict:
    """One task's total over its segment rows (module docstring)."""
    total: dict = {"task": task, "steps_requested": steps_requested, "segments": len(rows),
                   "seeds": [r["seed"] for r in rows]}
    for k in SUMMED:
        total[k] = int(sum(r[k] for r in rows))
    types: dict[str, int] = {}
    messages: dict[str, str] = {}
    for r in rows:
        for key, n in r.get("exception_types", {}).items():
            types[key] = types.get(key, 0) + int(n)
        for key, msg in r.get("exception_messages", {}).items():
            messages.setdefault(key, msg)
    total["exception_types"], total["exception_messages"] = types, messages
    total["max_peak_force_N"] = max((r["max_peak_force_N"] for r in rows), default=0.0)
    total["force_bound_N"] = rows[0]["force_bound_N"] if rows else math.nan

    def worst(key):
        vals = [r[key] for r in rows if r.get(key) is not None and not math.isnan(r[key])]
        return max(vals) if vals else None

    total["rss_growth_mb_max"] = worst("rss_growth_mb")
    total["rss_slope_mb_per_100k_max"] = worst("rss_slope_mb_per_100k")
    total["rss_start_mb"] = [r.get("rss_start_mb") for r in rows]
    total["rss_end_mb"] = [r.get("rss_end_mb") for r in rows]
    total["cpu_s_sum"] = float(sum(r["wall_s"] for r in rows))  # worker wall time, summed
    total["failures"] = sum(total[k] for k in ("nan", "exceptions", "unstable", "obs_out_of_space",
                                                "force_out_of_bounds"))
    total["complete"] = total["steps"] >= steps_requested
    return total


def json_safe(x):
    """Strict JSON: NaN/inf become null."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: json_safe(v) for k, v in x.items()}
    if isinstance(x, list):
        return [json_safe(v) for v in x]
    return x


def write_json(path: Path, data) -> None:
    """Write ``data`` to ``path`` atomically (a reader never sees half a file)."""
    path = Path(path)
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    tmp.write_text(json.dumps(json_safe(data), indent=2))
    os.replace(tmp, path)


def _nan_back(row: dict) -> dict:
    return {k: (math.nan if v is None and k.startswith("rss") else v) for k, v in row.items()}


def _safe(task: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]", "_", task)


def _worker(task, steps, seed, force_bound, max_seconds, sample_every, checkpoint_every, part, counter):  # child
    from surgsim_envs.bench.soak import soak

    row = soak(task, steps, seed, force_bound, max_seconds, sample_every, progress=False,
               checkpoint=lambda r: write_json(part, r), checkpoint_every=checkpoint_every, counter=counter)
    write_json(part, row)


def load_state(out: Path) -> dict:
    """The ``--out`` file's content, or an empty state; part files a killed run left are merged
    in (by seed: the longer row wins)."""
    out = Path(out)
    state = {"tasks": {}}
    if out.exists():
        try:
            state = json.loads(out.read_text())
        except (OSError, ValueError) as exc:
            raise ConfigError(f"cannot resume from {out}: not a soak JSON ({exc}); remove it or pass another --out") from None
        if not isinstance(state, dict) or not isinstance(state.get("tasks"), dict):
            raise ConfigError(f"cannot resume from {out}: no 'tasks' table; remove it or pass another --out")
    parts = out.with_name(out.name + ".parts")
    if parts.is_dir():
        for f in sorted(parts.glob("*.json")):
            try:
                row = json.loads(f.read_text())
            except (OSError, ValueError):
                continue  # a part being written when the run was killed: its previous checkpoint is lost
            _add_segment(state, row)
    return state


def _add_segment(state: dict, row: dict) -> None:
    entry = state["tasks"].setdefault(row["task"], {"segments": []})
    segs = entry["segments"]
    for i, s in enumerate(segs):
        if s["seed"] == row["seed"]:
            if row["steps"] > s["steps"]:
                segs[i] = row
            return
    segs.append(row)


def run_parallel(tasks: list[str], steps: int, seed: int = 0, workers: int = 2, out: str | Path = "soak.json",
                 resume: bool = False, force_bound: float = 50.0, max_seconds: float = math.inf,
                 sample_every: int = 1000, checkpoint_every: int = 10_000, progress: bool = True) -> list[dict]:
    """Soak every task in ``tasks`` with ``workers`` processes; returns the merged rows (and
    keeps ``out`` up to date)."""
    out = Path(out)
    if out.exists() and not resume:
        raise ConfigError(f"{out} exists: pass --resume to continue that soak, or another --out")
    if not out.parent.is_dir():
        raise ConfigError(f"--out {out}: folder {out.parent} does not exist")
    if isinstance(checkpoint_every, bool) or not isinstance(checkpoint_every, int) or checkpoint_every < 1:
        raise ConfigError(f"--checkpoint-every must be an integer >= 1 step, got {checkpoint_every!r}")
    split_steps(steps, workers)  # validates both
    state = load_state(out) if resume else {"tasks": {}}
    parts = out.with_name(out.name + ".parts")
    parts.mkdir(exist_ok=True)
    ctx = mp.get_context("spawn")
    try:
        for task in tasks:
            entry = state["tasks"].setdefault(task, {"segments": []})
            done = sum(s["steps"] for s in entry["segments"])
            used = {s["seed"] for s in entry["segments"]}
            k0 = len(entry["segments"])
            sizes = split_steps(max(steps - done, 0), workers)
            seeds, k = [], k0
            while len(seeds) < len(sizes):
                s = segment_seed(seed, k)
                k += 1
                if s not in used:
                    seeds.append(s)
                    used.add(s)
            counter = ctx.Value("q", 0)
            procs = [ctx.Process(target=_worker, name=f"soak-{k}", daemon=False,
                                 args=(task, n, s, force_bound, max_seconds, sample_every, checkpoint_every,
                                       parts / f"{_safe(task)}-{s}.json", counter))
                     for n, s in zip(sizes, seeds)]
            bar = None
            if progress and procs:
                from tqdm import tqdm

                bar = tqdm(total=steps, initial=min(done, steps), unit="step", desc=task, file=sys.stderr,
                           mininterval=1.0)
            try:
                for p in procs:
                    p.start()
                while any(p.is_alive() for p in procs):
                    time.sleep(0.5)
                    if bar is not None:
                        bar.update(min(done + counter.value, steps) - bar.n)
            except KeyboardInterrupt:
                for p in procs:
                    p.terminate()
                raise
            finally:
                for p in procs:
                    p.join(timeout=10.0)
                if bar is not None:
                    bar.close()
                for s in seeds:  # merge what the workers wrote, even after an interrupt
                    f = parts / f"{_safe(task)}-{s}.json"
                    if f.exists():
                        try:
                            _add_segment(state, json.loads(f.read_text()))
                        except (OSError, ValueError):
                            pass
                _save(out, state, steps)
                for s in seeds:
                    (parts / f"{_safe(task)}-{s}.json").unlink(missing_ok=True)
            failed = [p.name for p in procs if p.exitcode not in (0, None)]
            if failed:
                raise ConfigError(f"soak workers {failed} of {task} ended with an error (see above); "
                                  f"what they counted is in {out}: rerun with --resume")
    finally:
        _save(out, state, steps)
        try:
            parts.rmdir()  # only when empty
        except OSError:
            pass
    return [state["tasks"][t]["total"] for t in tasks]


def _save(out: Path, state: dict, steps: int) -> None:
    for task, entry in state["tasks"].items():
        entry["total"] = merge_rows(task, [_nan_back(r) for r in entry["segments"]], steps)
    state["load_avg"] = list(os.getloadavg())
    state["cpus"] = os.cpu_count()
    state["saved_utc"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    write_json(out, state)


def markdown_table(state: dict) -> str:
    """The docs/benchmarks.md soak table from an ``--out`` file's content (its merged rows)."""
    lines = ["| task | steps | segments | episodes | NaN | exceptions | unstable | obs out of space | "
             "force out of bounds | max peak force | RSS growth (worst worker) | RSS slope (worst worker) | complete |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for task, entry in sorted(state.get("tasks", {}).items()):
        t = entry.get("total") or merge_rows(task, [_nan_back(r) for r in entry["segments"]], 0)
        growth = "-" if t["rss_growth_mb_max"] is None else f"{t['rss_growth_mb_max']:+.2f} MB"
        slope = "-" if t["rss_slope_mb_per_100k_max"] is None else f"{t['rss_slope_mb_per_100k_max']:.2f} MB / 100k steps"
        lines.append(f"| {task} | {t['steps']:,} | {t['segments']} | {t['episodes']:,} | {t['nan']} | {t['exceptions']} | "
                     f"{t['unstable']} | {t['obs_out_of_space']} | {t['force_out_of_bounds']} | "
                     f"{t['max_peak_force_N']:.2f} N | {growth} | {slope} | {'yes' if t['complete'] else 'no'} |")
    return "\n".join(lines)
