"""The grasp tasks' reference readings level by level, with the task's jaws or rounded ones, at the
nodes or with contact samples between them.

Runs :func:`surgsim_envs.bench.probe_sets.slippage_pull.reference_row` (Slippage-v0: summed normal at
the hold, held pull, held contact force, mu 0.3 and 0.6) or
:func:`surgsim_envs.bench.probe_sets.grasp_closure.reference_row` (Grasp-v0: jaw normals of three
closures) at each spacing and prints one JSON line per level with its change from the level before.

    python scripts/grasp_reference_ladder.py --task SurgSim/Slippage-v0 --jaw-edges round \\
        --spacings 0.011,0.00778,0.0055,0.00389,0.00275
"""

from __future__ import annotations

import argparse
import json


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="SurgSim/Slippage-v0", choices=("SurgSim/Slippage-v0", "SurgSim/Grasp-v0"))
    parser.add_argument("--jaw-edges", default=None, choices=("sharp", "round"),
                        help="the jaws' edges in the tissue contact (default: the task's, sharp)")
    parser.add_argument("--samples", type=int, default=None,
                        help="contact samples: edge subdivisions n >= 2 (default: the nodes only)")
    parser.add_argument("--cache-mb", type=float, default=None,
                        help="fem_static's compliance column cache, MB (default 1000; about 6000 at 1.375 mm)")
    parser.add_argument("--graded-tip", type=float, default=None,
                        help="grade the lattice: the spacing only over this length (m) of the organ's tip, "
                             "2.75 mm along the rest (default: uniform)")
    parser.add_argument("--spacings", default="0.011,0.00778,0.0055,0.00389,0.00275", help="lattice spacings, m")
    args = parser.parse_args()
    if args.task == "SurgSim/Slippage-v0":
        from surgsim_envs.bench.probe_sets import slippage_pull as probes
    else:
        from surgsim_envs.bench.probe_sets import grasp_closure as probes
    last = None
    for h in (float(s) for s in args.spacings.split(",")):
        row = probes.reference_row(args.task, probes.FULL, h, jaw_edges=args.jaw_edges, surface_samples=args.samples,
                                   cache_mb=args.cache_mb, graded_tip=args.graded_tip)
        forces = row["forces_N"]
        change = ({k: round(100.0 * (v / last[k] - 1.0), 1) for k, v in forces.items() if last.get(k)}
                  if last else {})
        print(json.dumps({"spacing_mm": round(h * 1e3, 3), "nodes": row["nodes"], "seconds": round(row["seconds"], 1),
                          "forces_N": {k: round(v, 4) for k, v in forces.items()}, "change_pct": change}), flush=True)
        last = forces


if __name__ == "__main__":
    main()
