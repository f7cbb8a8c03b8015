"""Join the ``curve.json`` of consecutive (``--resume``d) training runs of scripts/train_sb3.py into
one learning-curve figure: episode return and training success rate against env steps, with
held-out evaluation levels as horizontal lines.

    python scripts/plot_learning_curves.py --runs runs/press_sac runs/press_sac2 runs/press_sac3 \
        --level "random (held out)=0.05" --level "trained, stochastic (held out)=0.7" \
        --title "SAC on SurgSim/PalpationPress-v0" --out docs/img/palpation_press_sac_learning_curve.png
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--runs", nargs="+", required=True, help="training output folders, in training order")
    p.add_argument("--level", action="append", default=[], help="LABEL=SUCCESS_RATE horizontal line (repeatable)")
    p.add_argument("--window", type=int, default=50, help="episodes per moving mean")
    p.add_argument("--title", default="learning curve")
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    levels = []
    for item in args.level:
        label, _, value = item.rpartition("=")
        try:
            levels.append((label, float(value)))
        except ValueError:
            p.error(f"--level {item!r} must be LABEL=NUMBER")
    args.levels = levels
    if args.window < 1:
        p.error("--window must be >= 1")
    return args


def main(argv=None) -> int:
    args = parse(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps, ret, ok, bounds = [], [], [], []
    for run in args.runs:
        curve = json.loads((Path(run) / "curve.json").read_text())
        if curve:
            bounds.append((curve[0][0], Path(run).name))
        for s, r, success, *_ in curve:
            steps.append(s)
            ret.append(r)
            ok.append(float(success))
    if not steps:
        raise SystemExit("no training episodes in the given runs")
    steps, ret, ok = map(np.asarray, (steps, ret, ok))
    k = min(args.window, len(ret))
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 4.2))
    ax.plot(steps, ret, ".", alpha=0.2, label="training episode return")
    ax.plot(steps[k - 1:], np.convolve(ret, np.ones(k) / k, mode="valid"), label=f"moving mean ({k} episodes)")
    ax2.plot(steps[k - 1:], np.convolve(ok, np.ones(k) / k, mode="valid"), color="C1",
             label=f"training episodes (stochastic), mean of {k}")
    for i, (label, value) in enumerate(args.levels):
        ax2.axhline(value, color=f"C{i + 2}", ls=["--", ":", "-.", (0, (5, 1))][i % 4], label=label)
    for a in (ax, ax2):
        for s, name in bounds[1:]:
            a.axvline(s, color="grey", lw=0.6)
        a.set_xlabel("environment steps")
    ax.set_ylabel("episode return")
    ax2.set_ylabel("success rate")
    ax2.set_ylim(-0.02, 1.02)
    ax.set_title(args.title)
    ax2.set_title("success (grey lines: resumed runs start)")
    ax.legend(fontsize=8)
    ax2.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=100)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
