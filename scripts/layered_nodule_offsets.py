"""How much LayeredPalpation-v0's force over the nodule depends on where the nodule sits on the lattice.

The nodule and the press over it are moved by (i, j) quarters of the spacing (i, j = 0-3, 16
positions) from the probe set's site, and the three presses over the nodule (2.5, 3.5, 4.5 mm) are
compared with the shipped reference's presses over the nodule: the reference's force over the
nodule does not depend on where the nodule sits to about 1 % (its 1 mm levels at (2, 1) and
(-1.5, 0.5) cm read 1.0-1.1 % apart), so one reference serves every position.

    python scripts/layered_nodule_offsets.py --model fem_hex --spacings 0.005,0.0033333333333333335,0.0025

Prints per spacing the smallest and largest error over the 16 positions, overall and per depth.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np

from surgsim_envs.bench.probe_sets import layered_palpation as lp
from surgsim_envs.tissue.task_table import TASK_TABLE_PATH


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", default="fem_hex", choices=lp.MODELS)
    ap.add_argument("--spacings", default="0.005,0.0033333333333333335,0.0025", help="comma-separated, m")
    args = ap.parse_args()
    with open(TASK_TABLE_PATH) as fh:
        ref = json.load(fh)["references"][lp.TASK]["forces_N"]
    over = [k for k in ref if "/over/" in k]
    for h in (float(v) for v in args.spacings.split(",")):
        t0, errors = time.time(), []
        for ox in np.arange(4) * h / 4:
            for oy in np.arange(4) * h / 4:
                pos = (lp.NODULE_XY[0] + ox, lp.NODULE_XY[1] + oy)
                probes = dataclasses.replace(lp.FULL, inclusions=(dataclasses.replace(lp.NODULE, position=pos),))
                f = lp.measure(lp.TASK, args.model, h, probes)["forces_N"]
                errors.append([f[k] / ref[k] - 1 for k in over])
        e = 100 * np.array(errors)
        depths = ", ".join(f"{k.rsplit('/', 1)[-1]} {a:+.1f} to {b:+.1f}" for k, a, b in zip(over, e.min(0), e.max(0)))
        print(f"{args.model} at {h * 1e3:.3g} mm, 16 positions: {e.min():+.1f} to {e.max():+.1f} % (per depth "
              f"{depths}); {time.time() - t0:.0f} s", flush=True)


if __name__ == "__main__":
    main()
