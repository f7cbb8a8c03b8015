"""Plot the rows of several ``surgsim bench accuracy`` JSON files on one speed-accuracy chart.

    python scripts/plot_accuracy_rows.py OUT.png A/accuracy.json B/accuracy.json ... [--models m1,m2]

Used for docs/img/accuracy_peers.png, accuracy_fem_static.png and accuracy_calibrated.png (subsets
of the rows of one ``surgsim bench accuracy`` run; the run's load is stated in docs/benchmarks.md).
``--models``: keep only these model names (default: every row). Same chart as ``surgsim bench
accuracy`` (:func:`surgsim_envs.bench.accuracy.plot`: log-log, Pareto front, real-time line)."""

import json
import sys

from surgsim_envs.bench.accuracy import plot


def main(argv: list[str]) -> int:
    models = None
    if "--models" in argv:
        i = argv.index("--models")
        if i + 1 >= len(argv):
            print("--models needs a comma-separated list of model names", file=sys.stderr)
            return 2
        models = {m.strip() for m in argv[i + 1].split(",") if m.strip()}
        argv = argv[:i] + argv[i + 2:]
    if len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    rows = []
    for path in argv[1:]:
        with open(path) as fh:
            rows += json.load(fh)["rows"]
    if models is not None:
        rows = [r for r in rows if r["model"] in models]
    if not rows:
        print(f"no rows{' for models ' + ','.join(sorted(models)) if models else ''}", file=sys.stderr)
        return 1
    plot(rows, argv[0])
    print(f"wrote {argv[0]} ({len(rows)} rows)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
