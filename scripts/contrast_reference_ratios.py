"""The reference contrast ratios of tests/test_task_force_invariants.py (REFERENCE_RATIOS): for each of
its CONTRAST_CASES (press site, press depth, inclusion contrast C) the force of a press over the
reported lump with contrast C over the same press with contrast 1, in the task-accuracy reference's
scene (surgsim_envs/bench/task_reference.py: fem_static on a lattice graded about the site, fine
spacing 2 mm, contact 1e8 N/m^3 per area with samples at half the spacing), physics step 0.25 ms,
the liver elastic with its friction. The reference's step matters: the reported case reads 1.317
at the task's 1 ms and 1.218 at 0.25 ms (docs/task_accuracy.md, "Nor is it converged in its time
step"). About 3 minutes on a 2-core host; the stiffness is factorised by PARDISO where pypardiso is
installed (the same solutions to 1e-15).

    python scripts/contrast_reference_ratios.py
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import surgsim_envs.tissue.fem_static as fem_static
from surgsim_envs.bench import task_accuracy as ta
from surgsim_envs.bench import task_reference as tr

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_task_force_invariants import CONTRAST_CASES, INCLUSION  # noqa: E402

TASK, FINE, DT = "SurgSim/Palpation-v0", 0.002, 2.5e-4


def _prefer_pardiso() -> None:
    init = fem_static.QuasiStaticFEMModel.__init__

    def with_solver(self, *args, **kwargs):
        kwargs.setdefault("solver", "auto")
        init(self, *args, **kwargs)

    fem_static.QuasiStaticFEMModel.__init__ = with_solver


def main() -> None:
    _prefer_pardiso()
    material = tr.elastic(ta.task_material(TASK))
    for site, depth, contrast in CONTRAST_CASES:
        forces = {}
        for c in (contrast, 1.0):
            env = ta.make_task_env(TASK, tr.REFERENCE_MODEL, tr.COARSE_SPACING, material=material, dt=DT)
            tr.graded_scene(env, site, FINE, depth)
            env.reset(seed=5, options={**INCLUSION, "stiffness_contrast": (c, c)})
            forces[c] = tr.descent_forces(env, site, (depth,))[0]
            env.close()
        print(f"    ({site}, {depth}, {contrast}): {forces[contrast] / forces[1.0]:.3f},   "
              f"# {forces[contrast]:.4f} / {forces[1.0]:.4f} N", flush=True)
    print(f"load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
