"""Would hexahedra help Palpation-v0? ``fem_static``'s step (condensed penalty contact with friction,
the palpation tasks' contact stiffness per area) with the rest stiffness of the box hexahedra with
incompatible modes (``tissue/hex_elements.py``; each cell's E the mean of its tets', its nu theirs)
instead of the tets', through the task-accuracy probe set against the shipped reference
(docs/models/fem_hex.md, "Where it does not help").

    python scripts/palpation_hex_stiffness.py SurgSim/Palpation-v0 0.01,0.0075,0.005
"""
import json
import sys
import time

import numpy as np

from surgsim_envs.tissue.fem_static import QuasiStaticFEMModel
from surgsim_envs.tissue import registry
from surgsim_envs.geometry.box_cells import box_cells
from surgsim_envs.tissue.hex_elements import HexAssembly
from surgsim_envs.bench import task_accuracy as ta
from surgsim_envs.tissue.task_table import TASK_TABLE_PATH


class HexStiffnessFEM(QuasiStaticFEMModel):
    """fem_static with the hexahedra's stiffness at rest (the rotated, dynamic paths keep the tets')."""

    name = "fem_static_hexk"

    def _assemble_stiffness(self, rotations, scale=None):
        if rotations is not None:
            return super()._assemble_stiffness(rotations, scale)
        if getattr(self, "_cells", None) is None:
            self._cells = box_cells(self.volume)
        c = self._cells
        mu, lam = self.mu, self.lam
        if scale is not None:
            mu, lam = mu * scale, lam * scale
        E = mu * (3 * lam + 2 * mu) / (lam + mu)
        nu = lam / (2 * (lam + mu))
        ncell = len(c.hexes)
        cnt = np.bincount(c.cell_of_tet, minlength=ncell)
        Ec = np.bincount(c.cell_of_tet, weights=E, minlength=ncell) / cnt
        nuc = np.bincount(c.cell_of_tet, weights=nu, minlength=ncell) / cnt
        nuc = np.round(nuc, 9)
        a = getattr(self, "_hexasm", None)
        if a is None or not np.array_equal(a.poisson, nuc):
            a = self._hexasm = HexAssembly(self.n_nodes, c.hexes, c.sizes, nuc)
        return a.stiffness(Ec)


registry.register("fem_static_hexk", HexStiffnessFEM, overwrite=True)
task = sys.argv[1] if len(sys.argv) > 1 else "SurgSim/Palpation-v0"
table = json.load(open(TASK_TABLE_PATH))
ref = table["references"][task]
probes = ta.PROBE_SETS[task][0]
for h in [float(v) for v in sys.argv[2].split(",")]:
    t = time.time()
    row = ta.compare(ta.measure(task, "fem_static_hexk", h, probes), ref, probes)
    print(h, row.get("nodes"), "p95 %.1f median %.1f" % (100 * row["error"], 100 * row["error_median"]) if "error" in row else row.get("refused"),
          "contrast", row.get("contrast"), "ref", row.get("contrast_reference"), "us/step %.0f" % row.get("us_per_env_step", 0), "%.0f s" % (time.time() - t), flush=True)
    if "forces_N" in row:
        print("   ", {k: round(100 * (row["forces_N"][k] / ref["forces_N"][k] - 1), 1) for k in ref["forces_N"]})
