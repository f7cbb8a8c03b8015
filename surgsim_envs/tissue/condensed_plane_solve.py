"""The condensed quasi-static step of ``fem_static`` with the contact's plane law solved exactly.

Equations (2)-(3) of :mod:`surgsim_envs.tissue.fem_static` linearise the contact force with one
isotropic stiffness per node. Given the contact's plane law instead
(:mod:`surgsim_envs.contact_law.plane`: per contact pair a unilateral penalty and Coulomb friction
on the pair's tangent plane, with the stick anchor from before the step), the loaded nodes A solve

    u_A = u0_A + W_AA g_A,     g_A = f_A - sum_p F_p(0) + sum_p F_p(u_A - u_A^n)

(W_AA / c and the hereditary base for a viscoelastic material, as in equation (4)). This is a
nonlinear block Gauss-Seidel over the pairs (the nonsmooth contact dynamics of Jean and Moreau, on
a compliance as in SOFA's precomputed-compliance solvers): each pair in turn solves its own law
against its node's 3x3 compliance with every other force held
(:func:`~surgsim_envs.contact_law.plane.solve_pair`), until no pair's force moves by more than
``tol`` of the largest. W_AA is symmetric positive definite, so a sticking or open contact set
converges like Gauss-Seidel on a positive definite system. Units: m, N.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surgsim_envs.contact_law.plane import F0, solve_pair
from surgsim_envs.tissue.compliance import respond, scaled_block


@njit(cache=True, nogil=True)
def find_loaded_law(forces, law_nodes, count, held, mark, out):
    """Write into ``out`` the free nodes with a non-zero force (N,3) or a contact pair of the plane
    law (``law_nodes[:count]``); return their count. ``mark`` (N,) int64 scratch, left zero."""
    for p in range(count):
        mark[law_nodes[p]] = 1
    m = 0
    for i in range(forces.shape[0]):
        if held[i]:
            mark[i] = 0
            continue
        if mark[i] != 0 or forces[i, 0] != 0.0 or forces[i, 1] != 0.0 or forces[i, 2] != 0.0:
            out[m] = i
            m += 1
        mark[i] = 0
    return m


@njit(cache=True, nogil=True)
def condensed_plane_solve(cols, slots, loaded, u0, forces, law_nodes, law_data, count, positions, rest, c, u,
                          applied, tol, max_sweeps, slot_of):
    """One quasi-static step of the loaded nodes with the plane law's ``count`` pairs solved by
    block Gauss-Seidel (module docstring). ``slot_of`` (N,) int64 scratch (left -1 where it was).
    Writes u (3N,) = u0 + C_A g / c and ``applied[loaded]`` = g (N); returns the sweeps taken
    (``max_sweeps + 1`` if the forces still moved by more than ``tol`` of the largest)."""
    m = loaded.shape[0]
    n3 = 3 * m
    w = scaled_block(cols, slots, loaded, c)
    for b in range(m):
        slot_of[loaded[b]] = b
    g = np.empty(n3)
    un = np.empty(n3)
    for b in range(m):
        i = loaded[b]
        for j in range(3):
            g[3 * b + j] = forces[i, j]
            un[3 * b + j] = positions[i, j] - rest[i, j]
    f = np.empty((count, 3))
    for p in range(count):           # start from the law at d = 0: g = forces
        for j in range(3):
            f[p, j] = law_data[p, F0 + j]
    ua = np.empty(n3)
    for d in range(n3):
        s = u0[3 * loaded[d // 3] + d % 3]
        for e in range(n3):
            s += w[d, e] * g[e]
        ua[d] = s
    a = np.empty((3, 3))
    d0 = np.empty(3)
    fn = np.empty(3)
    work = np.empty((5, 3))
    sweeps = 0
    for sweep in range(max_sweeps + 1):
        sweeps = sweep + 1
        if sweep == max_sweeps:
            break
        change = 0.0
        top = 0.0
        for p in range(count):
            b = slot_of[law_nodes[p]]
            for r in range(3):
                for q in range(3):
                    a[r, q] = w[3 * b + r, 3 * b + q]
            for r in range(3):
                d0[r] = ua[3 * b + r] - un[3 * b + r] - (a[r, 0] * f[p, 0] + a[r, 1] * f[p, 1] + a[r, 2] * f[p, 2])
            solve_pair(law_data[p], a, d0, fn, work)
            e0, e1, e2 = fn[0] - f[p, 0], fn[1] - f[p, 1], fn[2] - f[p, 2]
            if e0 != 0.0 or e1 != 0.0 or e2 != 0.0:
                for d in range(n3):
                    ua[d] += w[d, 3 * b] * e0 + w[d, 3 * b + 1] * e1 + w[d, 3 * b + 2] * e2
                g[3 * b] += e0
                g[3 * b + 1] += e1
                g[3 * b + 2] += e2
                f[p, 0], f[p, 1], f[p, 2] = fn[0], fn[1], fn[2]
            change = max(change, abs(e0), abs(e1), abs(e2))
            top = max(top, abs(fn[0]), abs(fn[1]), abs(fn[2]))
        if change <= tol * top:
            break
    for b in range(m):
        slot_of[loaded[b]] = -1
    respond(cols, slots, loaded, g, c, u0, u, applied)
    return sweeps


__all__ = ["condensed_plane_solve", "find_loaded_law"]
