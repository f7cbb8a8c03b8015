"""Factorisation and back-substitution cost of LayeredPalpation-v0's continuum wall (``model="fem_static"``)
with SuperLU (always installed) and MKL PARDISO (the optional ``pypardiso``), at the spacings given.

    python scripts/wall_factorisation.py 0.0025 0.002

Prints per spacing: free dofs, the stiffness's non-zeros, and per solver the factorisation time, the
time of 8 right-hand sides (unit forces: 8 compliance columns) and the residual. Wall times of one run
each (the factorisation is seconds to minutes); note the host's load alongside them.
"""

from __future__ import annotations

import sys
import time
from types import SimpleNamespace

import numpy as np
import scipy.sparse as sp

from surgsim_envs.envs.layered_palpation.wall import continuum_volume
from surgsim_envs.geometry.anatomy import ANATOMY_MATERIALS
from surgsim_envs.materials import PRESETS
from surgsim_envs.tissue import make
from surgsim_envs.tissue.compliance import CondensedCompliance, pardiso_available


def wall_stiffness(spacing: float):
    """(K on every dof, free mask) of the continuum wall at ``spacing`` m (the task's 8 x 6 cm patch)."""
    vol, planes = continuum_volume(SimpleNamespace(size=(0.08, 0.06), spacing=spacing))
    table = {**PRESETS, **ANATOMY_MATERIALS}
    mats = {k: table[name].replace(relax_fraction=0.0, friction=0.0) for k, (name, _, _) in enumerate(planes)}
    z_top = float(vol.nodes[:, 2].max())
    bottom = vol.nodes[:, 2] <= 1e-9 * z_top
    tissue = make("fem_static", vol, mats[0], fixed=np.flatnonzero(bottom), region_materials=mats)
    return sp.csr_matrix(tissue.stiffness_matrix()), np.repeat(~bottom, 3)


def main(argv=None) -> None:
    spacings = [float(a) for a in (argv if argv is not None else sys.argv[1:])] or [0.0025]
    solvers = ["superlu"] + (["pardiso"] if pardiso_available() else [])
    for h in spacings:
        k, free = wall_stiffness(h)
        n = int(free.sum())
        print(f"spacing {h * 1e3:g} mm: {n:,} free dofs, {k.nnz:,} non-zeros", flush=True)
        rhs = np.zeros((k.shape[0], 8))
        rhs[np.flatnonzero(free)[np.random.default_rng(0).choice(n, 8, replace=False)], np.arange(8)] = 1.0
        for solver in solvers:
            t0 = time.perf_counter()
            comp = CondensedCompliance(k, free, solver=solver)
            t_factor = time.perf_counter() - t0
            t0 = time.perf_counter()
            u = comp.solve(rhs)
            t_solve = time.perf_counter() - t0
            res = np.abs((k @ u)[free] - rhs[free]).max()
            print(f"  {solver:8s} factorise {t_factor:8.2f} s   8 columns {t_solve:6.3f} s   residual {res:.1e} N",
                  flush=True)
    if "pardiso" not in solvers:
        print("(pypardiso not installed: SuperLU only)")


if __name__ == "__main__":
    main()
