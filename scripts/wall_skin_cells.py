"""LayeredPalpation-v0's continuum wall (``model="fem_static"``) with the skin in cells of at most
SKIN_CELL m at x-y spacing H m: the probe set's presses against the shipped reference
(docs/task_accuracy.md, "The wall as a continuum").

    python scripts/wall_skin_cells.py H SKIN_CELL      # e.g. 0.0025 0.0005 (the task's cells: 0.001)
"""
import argparse
import json
import time

from surgsim_envs.bench.probe_sets import layered_palpation as lp
from surgsim_envs.envs.layered_palpation import wall
from surgsim_envs.tissue.task_table import TASK_TABLE_PATH

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("spacing", type=float, help="x-y lattice spacing, m (the task takes 0.002-0.01)")
parser.add_argument("skin_cell", type=float, help="tallest skin cell, m (the task's: 0.001)")
args = parser.parse_args()
wall.SKIN_CELL = args.skin_cell           # read when the wall's lattice is built
with open(TASK_TABLE_PATH) as fh:
    ref = json.load(fh)["references"][lp.TASK]["forces_N"]
t = time.perf_counter()
row = lp.measure(lp.TASK, "fem_static", args.spacing, lp.FULL)
err = {k: row["forces_N"][k] / ref[k] - 1 for k in ref}
print(f"spacing {args.spacing * 1e3:g} mm, skin cells <= {args.skin_cell * 1e3:g} mm: {row['nodes']} nodes, "
      f"{time.perf_counter() - t:.0f} s")
for k, e in err.items():
    print(f"  {k}: {row['forces_N'][k]:.4f} N ({100 * e:+.1f} % against the reference)")
print(f"  largest error {100 * max(abs(e) for e in err.values()):.1f} %")
