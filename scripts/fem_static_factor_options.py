"""Factorisations of fem_static's stiffness on Palpation-v0's default slab (5 mm, 5,292 free dofs):
time to factorise, fill (non-zeros in L + U) and time to back-substitute three compliance columns,
for SuperLU's column orderings and pivot/supernode options, MKL PARDISO (when the optional
``pypardiso`` is installed) and the averaged nodal pressure written as a mixed system (the nodal
pressures as unknowns beside the displacements). Every solution is compared with the default's.

    python scripts/fem_static_factor_options.py [--repeats 3]

Medians of ``--repeats`` factorisations and of 5 back-substitutions. docs/models/fem_static.md
quotes a run.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


def _median_time(fn, repeats: int):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3, help="factorisations per option (median)")
    args = ap.parse_args()

    import gymnasium as gym

    import surgsim_envs  # noqa: F401
    from surgsim_envs.tissue import fem_assembly as asm
    from surgsim_envs.tissue.compliance import CondensedCompliance, pardiso_available

    env = gym.make("SurgSim/Palpation-v0").unwrapped
    env.reset(seed=0)
    tissue = env.sim.tissue()
    free = tissue.compliance().free_index
    k = tissue.stiffness_matrix()
    kff = k[free][:, free].tocsc()
    rhs = np.zeros((len(free), 3))
    rhs[[10, len(free) // 2, len(free) - 10], [0, 1, 2]] = 1.0
    reference = spla.splu(kff, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True}).solve(rhs)
    print(f"{len(free):,} free dofs, {kff.nnz:,} non-zeros in K")

    def report(name, factorise, solve_rhs=rhs, rows=slice(None)):
        t_fact, lu = _median_time(factorise, args.repeats)
        t_solve, x = _median_time(lambda: lu.solve(solve_rhs), 5)
        fill = lu.L.nnz + lu.U.nnz if hasattr(lu, "L") else float("nan")
        diff = np.abs(x[rows] - reference).max() / np.abs(reference).max()
        print(f"{name:58s} factorise {t_fact:6.3f} s  fill {fill / 1e6:5.2f} M  3 columns "
              f"{1e3 * t_solve:6.2f} ms  vs default {diff:.1e}")

    for perm in ("MMD_AT_PLUS_A", "COLAMD", "MMD_ATA"):
        for thresh in (1.0, 0.0):
            for relax in (None, 32):
                kw = dict(permc_spec=perm, diag_pivot_thresh=thresh,
                          options={"SymmetricMode": True} if perm == "MMD_AT_PLUS_A" else {})
                if relax:
                    kw.update(relax=relax, panel_size=16)
                report(f"SuperLU {perm}, diag_pivot_thresh {thresh}, relax {relax or 'default'}",
                       lambda kw=kw: spla.splu(kff, **kw))
    if pardiso_available():
        mask = np.zeros(k.shape[0], dtype=bool)
        mask[free] = True
        report("MKL PARDISO Cholesky", lambda: CondensedCompliance(k, mask, cache_mb=1.0, solver="pardiso").lu)
    else:
        print("MKL PARDISO: not installed (pip install pypardiso)")

    # the averaged nodal pressure as a mixed system: K = K_dev + Bv^T diag(kappa V) Bv
    n = tissue.n_nodes
    bv = asm.anp_volume_operator(tissue.tets, tissue.grads, tissue.tet_volume, n)
    kv = tissue.kappa_node * asm.nodal_volumes(tissue.tets, tissue.tet_volume, n)
    kdev = (k - bv.T @ sp.diags(kv) @ bv).tocsr()
    mixed = sp.bmat([[kdev[free][:, free], bv.T[free]], [bv[:, free], sp.diags(-1.0 / kv)]]).tocsc()
    report(f"SuperLU MMD_AT_PLUS_A, mixed (u, p): {mixed.shape[0]:,} unknowns",
           lambda: spla.splu(mixed, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True}),
           np.vstack([rhs, np.zeros((n, 3))]), slice(0, len(free)))


if __name__ == "__main__":
    main()
