"""Plot the rows of several ``surgsim bench accuracy`` JSON files on one speed-accuracy chart.

    python scripts/plot_accuracy_rows.py OUT.png A/accuracy.json B/accuracy.json ...

Used for docs/img/accuracy_peers.png (our models from one run, the PyBullet peers from another:
both runs' load is stated in docs/benchmarks.md). Same chart as ``surgsim bench accuracy``
(:func:`surgsim_envs.bench.accuracy.plot`: log-log, Pareto front, real-time line)."""

import json
import sys

from surgsim_envs.bench.accuracy import plot


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    rows = []
    for path in argv[1:]:
        with open(path) as fh:
            rows += json.load(fh)["rows"]
    plot(rows, argv[0])
    print(f"wrote {argv[0]} ({len(rows)} rows)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
