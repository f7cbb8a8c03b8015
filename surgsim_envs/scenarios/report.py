"""Reports of scenario runs: ``report.json``, ``forces.png``, ``report.md`` (and the run's video).

``report.json``::

    {"scenario": name, "description": ..., "score": 0-100 (mean over runs), "passed": bool,
     "criteria": {name: {"value", "unit", "target", "limit", "weight", "score", "passed"}},  # first run
     "safety": {"limit": N, "violations": [{"start", "end", "duration" s, "peak" N}]},        # first run
     "phases": [{"index", "type", "label", "driver", "start", "end"}],
     "metrics": {...},
     "runs": [{<sweep values, e.g. "mu">, "score", "passed", "completed", "slip_onset_pull" N,
               "slip_onset_time" s, "peak_normal" N, "normal_end_close" N, "normal_end_hold" N,
               "relaxed_fraction", "close_linearity_r2", "criteria", "violations", "metrics"}],
     "files": {...}}

``forces.png``: normal (top) and tangential (bottom) force against time, one line per run,
phases shaded, the safety limit dashed, violations in red and slip onsets as red dots
(the grasping simulation paper, Figs. 4 and 5).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

_PHASE_COLOURS = {"approach": "#dde8f5", "close_jaws": "#e6f2e0", "hold": "#fbf3d9", "pull": "#f8e1e1",
                  "press": "#e9e1f5", "palpate": "#e9e1f5", "release": "#eeeeee"}


def _clean(value):
    """JSON-safe copy (numpy scalars, NaN -> None)."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        return _clean(value.tolist())
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, (np.integer,)):
        return int(value)
    return value


def run_summary(res) -> dict:
    """The ``runs`` entry of one :class:`~surgsim_envs.scenarios.recording.RunResult`."""
    m = res.metrics
    onset = m.get("slip_onset") or {}
    out = dict(res.values)
    out.update({
        "score": res.score, "passed": res.passed, "completed": res.completed, "error": res.error,
        "slip_onset_pull": onset.get("pull_force"), "slip_onset_time": onset.get("time"),
        "peak_normal": m.get("peak_force"), "peak_tangential": m.get("peak_tangential_force"),
        "peak_pull": m.get("peak_pull_force"), "normal_end_close": m.get("normal_end_close"),
        "normal_end_hold": m.get("normal_end_hold"), "relaxed_fraction": m.get("relaxed_fraction"),
        "close_linearity_r2": m.get("close_linearity_r2"), "slip_events": m.get("slip_events"),
        "criteria": {c.name: c.as_dict() for c in res.criteria},
        "violations": res.violations, "phases": res.recording.phase_spans, "metrics": m,
        "wall_time_s": res.wall_time, "info": res.info,
    })
    return out


def build_report(results) -> dict:
    """The report dictionary of a list of runs of one scenario."""
    if not results:
        raise ValueError("no runs to report")
    first = results[0]
    sc = first.scenario
    return _clean({
        "scenario": sc.name, "description": sc.meta.description, "source": str(sc.source) if sc.source else None,
        "duration_scale": sc.meta.duration_scale,
        "score": float(np.mean([r.score for r in results])), "passed": all(r.passed for r in results),
        "completed": all(r.completed for r in results),
        "criteria": {c.name: c.as_dict() for c in first.criteria},
        "safety": {"limit": sc.scoring.safety_limit, "violations": first.violations,
                   "violations_per_run": [len(r.violations) for r in results]},
        "phases": first.recording.phase_spans, "metrics": first.metrics,
        "runs": [run_summary(r) for r in results],
    })


def _label(res) -> str:
    return ", ".join(f"{k} = {v}" for k, v in res.values.items()) or res.scenario.name


def plot_forces(results, path, title: str | None = None) -> Path:
    """Write ``forces.png``: normal (top) and tangential (bottom) force vs time for every run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    first = results[0]
    limit = first.scenario.scoring.safety_limit
    for ax in axes:
        for span in first.recording.phase_spans:
            ax.axvspan(span["start"], span["end"], color=_PHASE_COLOURS.get(span["type"], "#f0f0f0"), lw=0, zorder=0)
    for span in first.recording.phase_spans:
        axes[0].text((span["start"] + span["end"]) / 2, 1.0, span["label"], transform=axes[0].get_xaxis_transform(),
                     ha="center", va="bottom", fontsize=8, color="#555555")
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    onset_labelled = False
    for k, res in enumerate(results):
        rec, c = res.recording, colours[k % len(colours)]
        axes[0].plot(rec.t, rec.normal, color=c, lw=1.4, label=_label(res))
        axes[1].plot(rec.t, rec.tangential, color=c, lw=1.4, label=_label(res))
        onset = res.metrics.get("slip_onset")
        if onset:
            i = int(np.argmin(np.abs(rec.t - onset["time"])))
            for ax, series in ((axes[0], rec.normal), (axes[1], rec.tangential)):
                ax.plot([rec.t[i]], [series[i]], "o", color="red", ms=6, zorder=5,
                        label=None if onset_labelled or ax is axes[0] else "slip onset")
            onset_labelled = True
        for v in res.violations:
            axes[0].axvspan(v["start"], v["end"], color="red", alpha=0.25, lw=0, zorder=1)
            axes[0].plot([v["start"]], [v["peak"]], "v", color="red", ms=6)
    axes[0].axhline(limit, color="red", ls="--", lw=1, label=f"safety limit {limit:g} N")
    axes[0].set_ylabel("normal force (N)")
    axes[1].set_ylabel("tangential force (N)")
    axes[1].set_xlabel("time (s)")
    top = max(float(np.nanmax(r.recording.normal)) if len(r.recording.t) else 0.0 for r in results)
    axes[0].set_ylim(0, max(top, limit) * 1.12 + 1e-6)
    axes[0].legend(fontsize=8, loc="upper left")
    axes[1].legend(fontsize=8, loc="upper left")
    fig.suptitle(title or f"{first.scenario.name}: tool-tissue forces", fontsize=11)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _fmt(v, unit=""):
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.4g}{(' ' + unit) if unit else ''}"
    return f"{v}{(' ' + unit) if unit else ''}"


def number_text(v, spec: str) -> str:
    """``v`` formatted with ``spec``, or "-" for a missing (None) or non-finite value."""
    return "-" if v is None or not math.isfinite(v) else format(v, spec)


def markdown(report: dict) -> str:
    """A short human-readable summary of a report dictionary."""
    lines = [f"# Scenario report: {report['scenario']}", ""]
    if report.get("description"):
        lines += [report["description"], ""]
    lines += [f"**Score: {number_text(report['score'], '.1f')} / 100** — {'PASSED' if report['passed'] else 'NOT PASSED'}"
              f" ({len(report['runs'])} run{'s' if len(report['runs']) != 1 else ''}, duration scale "
              f"{report['duration_scale']:g})", ""]
    lines += ["| criterion | value | target | limit | weight | score | passed |", "|---|---|---|---|---|---|---|"]
    for name, c in report["criteria"].items():
        lines.append(f"| {name} | {_fmt(c['value'], c['unit'])} | {_fmt(c['target'])} | {_fmt(c['limit'])} | "
                     f"{_fmt(c['weight'])} | {number_text(c['score'], '.2f')} | {'yes' if c['passed'] else 'no'} |")
    v = report["safety"]["violations"]
    lines += ["", f"Safety limit {report['safety']['limit']:g} N: "
                  + ("no violations." if not v else f"{len(v)} violation(s): "
                     + "; ".join(f"{x['start']:.2f}-{x['end']:.2f} s (peak {x['peak']:.2f} N)" for x in v[:10]))]
    if len(report["runs"]) > 1 or report["runs"][0].get("slip_onset_pull") is not None:
        keys = [k for k in report["runs"][0] if k not in _RUN_KEYS]
        lines += ["", "| " + " | ".join(keys + ["score", "peak normal (N)", "end of close (N)", "end of hold (N)",
                                              "slip onset pull (N)", "slip onset t (s)"]) + " |",
                  "|" + "---|" * (len(keys) + 6)]
        for r in report["runs"]:
            lines.append("| " + " | ".join([_fmt(r[k]) for k in keys] + [
                number_text(r["score"], ".1f"), _fmt(r["peak_normal"]), _fmt(r["normal_end_close"]), _fmt(r["normal_end_hold"]),
                _fmt(r["slip_onset_pull"]), _fmt(r["slip_onset_time"])]) + " |")
    lines += ["", "Phases: " + ", ".join(f"{p['label']} ({p['driver']}, {p['start']:.2f}-{p['end']:.2f} s)"
                                         for p in report["phases"]), ""]
    for err in report.get("write_errors", []):
        lines += [f"Not written: {err}", ""]
    files = report.get("files", {})
    if files:
        lines += ["Files: " + ", ".join(f"[{k}]({Path(v).name})" for k, v in files.items() if v), ""]
    return "\n".join(lines)


_RUN_KEYS = {"score", "passed", "completed", "error", "slip_onset_pull", "slip_onset_time", "peak_normal",
             "peak_tangential", "peak_pull", "normal_end_close", "normal_end_hold", "relaxed_fraction",
             "close_linearity_r2", "slip_events", "criteria", "violations", "phases", "metrics", "wall_time_s", "info"}


def _finite_or_none(value):
    """``value`` with every non-finite float replaced by None (report.json stays valid JSON)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_or_none(v) for v in value]
    return value


def write_report(results, out_dir, *, timeseries: bool = True) -> dict:
    """Write report.json, forces.png, report.md (and timeseries.npz) into ``out_dir``; return the report.

    A run writes what it has: a plot or time series that cannot be written is named in
    ``report["write_errors"]`` and report.json / report.md are written all the same."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = build_report(results)
    files = {"json": str(out / "report.json"), "markdown": str(out / "report.md")}
    errors = []
    try:
        files["plot"] = str(plot_forces(results, out / "forces.png"))
    except Exception as exc:  # noqa: BLE001 - the report is written without the plot
        errors.append(f"forces.png not written ({type(exc).__name__}: {exc})")
    videos = [r.info.get("video") for r in results if r.info.get("video")]
    if videos:
        files["video"] = videos[0] if len(videos) == 1 else ", ".join(videos)
    if timeseries:
        try:
            arrays = {}
            for k, r in enumerate(results):
                for name in r.recording.FIELDS:
                    arrays[f"run{k}_{name}"] = getattr(r.recording, name)
                arrays[f"run{k}_position"] = r.recording.position
            np.savez_compressed(out / "timeseries.npz", **arrays)
            files["timeseries"] = str(out / "timeseries.npz")
        except Exception as exc:  # noqa: BLE001 - the report is written without the time series
            errors.append(f"timeseries.npz not written ({type(exc).__name__}: {exc})")
    report["files"] = files
    if errors:
        report["write_errors"] = errors
    report = _finite_or_none(report)
    (out / "report.json").write_text(json.dumps(report, indent=2, allow_nan=False))
    (out / "report.md").write_text(markdown(report))
    return report
