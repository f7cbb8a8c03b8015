"""LayeredPalpation-v0's held-out press set: the task's nodule at another position, pressed over it
and at its mirror site to the probe set's depths, by the graded FEM reference of the task-accuracy
table (``layered_palpation.reference_row``) at one fine spacing. Writes the JSON that
``tests/test_fem_hex.py`` holds the task's default to (shipped as
``surgsim_envs/tissue/data/layered_palpation_heldout_reference.json``).

    python scripts/layered_heldout_reference.py --out FILE [--xy -0.015 0.005] [--fine 0.001]   # ~8 min, 6 GB
"""
import argparse
import dataclasses
import json
import time

from surgsim_envs.bench.probe_sets import layered_palpation as lp

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", required=True)
parser.add_argument("--xy", type=float, nargs=2, default=(-0.015, 0.005), help="nodule centre x y, m")
parser.add_argument("--fine", type=float, default=0.001, help="the reference's fine spacing at the press site, m")
args = parser.parse_args()
probes = dataclasses.replace(lp.FULL, inclusions=(dataclasses.replace(lp.NODULE, position=tuple(args.xy)),))
t = time.perf_counter()
row = lp.reference_row(lp.TASK, probes, args.fine)
out = {"task": lp.TASK, "position": list(args.xy), "fine": args.fine, "seconds": time.perf_counter() - t,
       "source": "python scripts/layered_heldout_reference.py (layered_palpation.reference_row)",
       "forces_N": row["forces_N"]}
with open(args.out, "w") as fh:
    json.dump(out, fh, indent=1)
print(json.dumps(out, indent=1))
