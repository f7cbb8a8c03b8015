"""Held force of the grasp-and-pull rig against mu: the pull the grasp holds before it slides,
over mu times the jaws' normal force, for mu in 0.1-1.5 (docs/material_tests.md, "Slip onset").

    PYTHONPATH=. python scripts/slip_held_ratio.py --models mass_spring,fem --slow-low-mu --distances 5e-5,2e-4 \
        --out docs/img/slip_held_ratio.png

Per mu it runs :func:`surgsim_envs.bench.material.slip` (default rig, onset from the contact
state) and records: the held force (largest pull up to the onset) over mu x the normal force at
the instant it was reached and over mu x the normal force when the pull began; the normal
force's drop by then; the friction's share of its cap at the onset (|sum f_t| / (mu sum f_n));
the ratio while sliding (the ``after_onset`` record); the held ratio for other slid-share
thresholds (0.8, 0.95), read from the same run; and each contact point's slip against its normal
force when a quarter of the points have slid and at the onset. ``--distances`` reruns some mu
with other slip distances. Writes the figure and a JSON file next to it (``--replot`` redraws
the figure from it).
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from surgsim_envs.bench.material import slip
from surgsim_envs.bench.slip_onset import SLIP_DISTANCE, gross_slip_index

MUS = (0.1, 0.2, 0.3, 0.5, 0.75, 1.0, 1.25, 1.5)


def _slip_distance(kw: dict) -> float:
    return kw.get("slip_distance", SLIP_DISTANCE)


def _held(r, j: int) -> tuple[float, float]:
    """(held force N, normal force N at the instant it was reached) for an onset at sample j."""
    h = int(np.argmax(r.pull[:j + 1]))
    return float(r.pull[h]), float(r.normal_sum[h])


def measure(model: str, mu: float, **kw) -> dict:
    t0 = time.perf_counter()
    r = slip(model, mu=mu, **kw)
    wall = time.perf_counter() - t0
    k = gross_slip_index(r.slid_share)
    after = r.time > r.time[k]
    alt = {}
    for share in (0.8, 0.95):
        j = gross_slip_index(r.slid_share, share)
        alt[str(share)] = None if j is None else (lambda hn: hn[0] / (mu * hn[1]))(_held(r, j))
    # where the slip starts: the first snapshot at which a quarter of the contact points (by count)
    # has slid, and the onset; each contact point's slip against its normal force
    profiles = {}
    part = None
    for q in range(len(r.node_slip_time)):
        touch = r.node_normal[q] > 0
        slid = touch & (r.node_slip[q] >= _slip_distance(kw))
        if touch.any() and slid.sum() >= 0.25 * touch.sum():
            part = q
            break
    on = int(np.argmin(np.abs(r.node_slip_time - r.time[k])))
    for name, q in (("partial", part), ("onset", on)):
        if q is None:
            continue
        touch = r.node_normal[q] > 0
        n, sl = r.node_normal[q][touch], r.node_slip[q][touch]
        slid = sl >= _slip_distance(kw)
        profiles[name] = {"t": float(r.node_slip_time[q]), "z": r.node_z[touch].tolist(), "slip": sl.tolist(),
                          "normal": n.tolist(), "count_share": float(slid.mean()),
                          "normal_share": float(n[slid].sum() / n.sum()),
                          "median_normal_slid": float(np.median(n[slid])) if slid.any() else None,
                          "median_normal_stuck": float(np.median(n[~slid])) if (~slid).any() else None}
    return {"mu": mu, "model": r.model, "wall_s": wall, "handle_speed": kw.get("handle_speed", 0.01),
            "onset_time": float(r.time[k]), "onset_pull": r.slip_onset_pull, "held_pull": r.held_pull,
            "held_normal": r.held_normal, "normal_onset": r.slip_onset_normal, "normal_start": r.normal_start,
            "held_over_mu_n": r.held_pull / (mu * r.held_normal),
            "held_over_mu_n_start": r.held_pull / (mu * r.normal_start),
            "normal_drop": 1.0 - r.held_normal / r.normal_start,
            "mobilised_onset": float(r.mobilised[k]),
            "sliding_ratio": float(np.mean(r.pull[after] / (mu * r.normal_sum[after]))) if after.any() else None,
            "held_over_mu_n_share": alt, "profiles": profiles,
            "curve": {"time": r.time[::20].tolist(), "pull": r.pull[::20].tolist(),
                      "normal": r.normal_sum[::20].tolist(), "slid_share": r.slid_share[::20].tolist(),
                      "mobilised": r.mobilised[::20].tolist()}}


def plot(runs: dict[str, list[dict]], path: str, curve_mu: float) -> None:
    """Panel a: the ratios against mu for every model; b and c: one pull of the first model."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b, c) = plt.subplots(1, 3, figsize=(16, 4.6))
    a.axhline(1.0, color="0.6", lw=0.8)
    for colour, (model, rows) in zip(("C0", "C1", "C2"), runs.items()):
        mu = np.array([r["mu"] for r in rows])
        ratio = np.array([r["held_over_mu_n"] for r in rows])
        vals = [[v for v in [*r["held_over_mu_n_share"].values(), r["held_over_mu_n"]] if v is not None] for r in rows]
        lo, hi = np.array([min(v) for v in vals]), np.array([max(v) for v in vals])
        a.errorbar(mu, ratio, yerr=[ratio - lo, hi - ratio], fmt="o-", color=colour, capsize=3, lw=2.2,
                   label=f"{model}: held / (mu N), N at the same instant")
        a.plot(mu, [r["held_over_mu_n_start"] for r in rows], "s--", color=colour,
               label=f"{model}: held / (mu N before the pull)")
        a.plot(mu, [1.0 - r["normal_drop"] for r in rows], "x:", color=colour,
               label=f"{model}: N when held / N before the pull")
        a.plot(mu, [r["mobilised_onset"] for r in rows], "^-.", color=colour, lw=0.8, ms=4,
               label=f"{model}: |sum f_t| / (mu sum f_n) at onset")
    a.set_xlabel("mu")
    a.set_ylabel("ratio (bars: onset at slid share 0.8-0.95)")
    a.set_ylim(0.4, 1.1)
    a.set_title("held force against mu")
    a.legend(fontsize=6.5, loc="lower left")
    rows = next(iter(runs.values()))
    r = min(rows, key=lambda q: abs(q["mu"] - curve_mu))
    cv = r["curve"]
    t = np.array(cv["time"])
    b.plot(t, cv["pull"], label="pull (N)")
    b.plot(t, r["mu"] * np.array(cv["normal"]), "--", label="mu x sum N (N)")
    b.plot(t, cv["slid_share"], ":", label="share of N on slid points")
    b.plot(t, cv["mobilised"], "-.", lw=0.8, label="|sum f_t| / (mu sum f_n)")
    b.axvline(r["onset_time"], color="r", lw=0.8, label="onset (share 0.9)")
    b.set_xlabel("time since the pull began (s)")
    b.set_title(f"mu = {r['mu']}: one pull")
    b.legend(fontsize=7)
    for name, style in (("partial", "o"), ("onset", "x")):
        p = r["profiles"].get(name)
        if p is None:
            continue
        c.plot(np.array(p["normal"]) * 1e3, np.array(p["slip"]) * 1e3, style, ms=3,
               label=f"t = {p['t']:.2f} s: {p['count_share']:.0%} of the points slid, carrying "
                     f"{p['normal_share']:.0%} of N")
    c.axhline(1e3 * SLIP_DISTANCE, color="0.5", lw=0.8, label="slip distance 0.1 mm")
    c.set_xlabel("normal force on the contact point (mN)")
    c.set_ylabel("slip along the jaws since the pull began (mm)")
    c.set_title(f"mu = {r['mu']}: the lightly loaded points slide first")
    c.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def prune(runs: dict[str, list[dict]], curve_mu: float) -> None:
    """Keep the time curve and the slip profiles of the plotted pull only (the JSON stays small)."""
    first = next(iter(runs))
    for model, rows in runs.items():
        keep = min(rows, key=lambda q: abs(q["mu"] - curve_mu)) if model == first else None
        for r in rows:
            if r is not keep:
                r.pop("curve", None)
                r.pop("profiles", None)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", default="mass_spring", help="comma-separated; the first gets the one-pull panels")
    ap.add_argument("--mus", default=",".join(str(m) for m in MUS))
    ap.add_argument("--distances", default="", help="slip distances (m) to rerun at --distance-mus, e.g. 5e-5,2e-4")
    ap.add_argument("--distance-mus", default="0.3,1.0")
    ap.add_argument("--out", default="docs/img/slip_held_ratio.png")
    ap.add_argument("--curve-mu", type=float, default=1.0)
    ap.add_argument("--replot", default=None, metavar="JSON", help="redraw the figure from a written JSON file")
    ap.add_argument("--slow-low-mu", action="store_true",
                    help="handle at 0.01 min(1, mu / 0.3) m/s, so the pull ramps over several periods of the "
                         "tissue on the handle spring at low mu (quasi-static; the default rig overshoots by "
                         "inertia at mu 0.1)")
    args = ap.parse_args()
    if args.replot:
        with open(args.replot) as f:
            plot(json.load(f)["runs"], args.out, args.curve_mu)
        return
    runs, extra = {}, []
    for model in args.models.split(","):
        rows = runs.setdefault(model, [])
        for mu in (float(m) for m in args.mus.split(",")):
            kw = {"handle_speed": 0.01 * min(1.0, mu / 0.3)} if args.slow_low_mu else {}
            rows.append(measure(model, mu, **kw))
            q = rows[-1]
            print(f"{model} mu {mu}: held {q['held_pull']:.4f} N = {q['held_over_mu_n']:.3f} mu N = "
                  f"{q['held_over_mu_n_start']:.3f} mu N_start; N drop {q['normal_drop']:.3f}; mobilised "
                  f"{q['mobilised_onset']:.3f}; sliding {q['sliding_ratio']:.3f}; share 0.8/0.95: "
                  f"{q['held_over_mu_n_share']}; {q['wall_s']:.0f} s", flush=True)
        for d in (float(x) for x in args.distances.split(",") if x):
            for mu in (float(m) for m in args.distance_mus.split(",")):
                kw = {"handle_speed": 0.01 * min(1.0, mu / 0.3)} if args.slow_low_mu else {}
                q = measure(model, mu, slip_distance=d, **kw)
                q.pop("curve")
                q.pop("profiles")
                q["slip_distance"] = d
                extra.append(q)
                print(f"{model} slip distance {d} m, mu {mu}: held / (mu N) {q['held_over_mu_n']:.3f}", flush=True)
    plot(runs, args.out, args.curve_mu)
    prune(runs, args.curve_mu)
    with open(os.path.splitext(args.out)[0] + ".json", "w") as f:
        json.dump({"slow_low_mu": args.slow_low_mu, "uptime": os.popen("uptime").read().strip(), "runs": runs,
                   "slip_distance_reruns": extra}, f, indent=1)

if __name__ == "__main__":
    main()
