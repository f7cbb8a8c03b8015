"""numba kernels of the ``layered`` model's prefactored contact step (Lin et al. 2008, eqs. 2.5 and 2.8).

The springs' scalar Laplacian ``A`` of the free (non-anchor) nodes is factorised once; a node ``c``
that carries a reaction (a contact node held on the tool, or an end of a rigid extreme-length
link) has a cached compliance row ``Gt[slot_of[c]] = A^-1 e_c`` (``Gt`` is (slots, free nodes):
row k is the displacement of every free node under a unit load at the node of slot k). Per axis
``a`` the step solves the reactions of the constrained nodes U only:

    E G_UU E^T lam = t - E v0_U,        w = E^T lam,        u_a = v0_a + sum_U Gt[U] w_U     (1)

(E: one row per constraint: a contact node held at its target displacement ``t``, or a rigid link
holding ``u_j - u_i = -s0`` with ``s0`` = rest separation - extreme length). The displacements of
any node follow from (1) on demand: a step writes only the nodes near the contact (the force and
the extreme-length check need them), the rest when something reads them (lazy recovery).
Units: m, N, N/m.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def unique_reacting(contact, link_i, link_j, anchor, mark, stamp, pos_of):
    """Unique non-anchor nodes of ``contact`` then the link ends, in first-seen order; ``mark``
    (N,) int64 stamps with ``stamp``, ``pos_of`` (N,) their index in the result."""
    out = np.empty(contact.shape[0] + 2 * link_i.shape[0], dtype=np.int64)
    m = 0
    for q in range(contact.shape[0] + 2 * link_i.shape[0]):
        if q < contact.shape[0]:
            c = contact[q]
        elif q < contact.shape[0] + link_i.shape[0]:
            c = link_i[q - contact.shape[0]]
        else:
            c = link_j[q - contact.shape[0] - link_i.shape[0]]
        if anchor[c] or mark[c] == stamp:
            continue
        mark[c] = stamp
        pos_of[c] = m
        out[m] = c
        m += 1
    return out[:m]


@njit(cache=True, nogil=True)
def write_rows(nodes, local, slots, w3, Gt, v0, rest, fixed, fixed_targets, x, xstamp, version):
    """x[nodes] from eq. (1) (``w3`` (3,U) loads on the nodes of ``slots`` (U,); Dirichlet nodes at
    their targets); stamps ``xstamp`` = ``version``. Returns False if a value is not finite."""
    acc = np.empty((nodes.shape[0], 3))
    for q in range(nodes.shape[0]):
        i = nodes[q]
        r = local[i]
        for a in range(3):
            acc[q, a] = rest[i, a] + (v0[r, a] if r >= 0 else 0.0)
    for k in range(slots.shape[0]):
        row = slots[k]
        for q in range(nodes.shape[0]):
            r = local[nodes[q]]
            if r >= 0:
                g = Gt[row, r]
                for a in range(3):
                    acc[q, a] += g * w3[a, k]
    ok = True
    for q in range(nodes.shape[0]):
        i = nodes[q]
        for a in range(3):
            if fixed[i] or local[i] < 0:
                x[i, a] = fixed_targets[i, a]
            else:
                x[i, a] = acc[q, a]
                if not np.isfinite(acc[q, a]):
                    ok = False
        xstamp[i] = version
    return ok


@njit(cache=True, nogil=True)
def rows_positions(nodes, local, slots, w3, Gt, v0, rest, fixed, fixed_targets, out):
    """(K,3) positions of ``nodes`` from eq. (1) without writing the model."""
    for q in range(nodes.shape[0]):
        i = nodes[q]
        r = local[i]
        for a in range(3):
            if fixed[i] or r < 0:
                out[q, a] = fixed_targets[i, a]
            else:
                s = rest[i, a] + v0[r, a]
                for k in range(slots.shape[0]):
                    s += Gt[slots[k], r] * w3[a, k]
                out[q, a] = s


@njit(cache=True, nogil=True)
def fd_velocities(nodes, before, before_stamp, version, x, vel, inv_dt):
    """Finite-difference velocities of ``nodes`` whose previous positions were current at the
    previous step (``before_stamp == version - 1``); the others get 0."""
    for q in range(nodes.shape[0]):
        i = nodes[q]
        for a in range(3):
            vel[i, a] = (x[i, a] - before[q, a]) * inv_dt if before_stamp[q] == version - 1 else 0.0


@njit(cache=True, nogil=True)
def all_fresh(nodes, nbr, xstamp, version, local, fixed):
    """True if every one of ``nodes`` and their NBB neighbours has a current position."""
    for q in range(nodes.shape[0]):
        i = nodes[q]
        if xstamp[i] != version and local[i] >= 0 and not fixed[i]:
            return False
        for d in range(6):
            j = nbr[i, d]
            if j >= 0 and xstamp[j] != version and local[j] >= 0 and not fixed[j]:
                return False
    return True


@njit(cache=True, nogil=True)
def solve_step(contact, t_c, link_i, link_a, s0, uniq, pos_of, anchor, local, slot_of, Gt, v0, nbr, lmin, nodes,
               rest, fixed, fixed_targets, x, xstamp, version, mark, stamp, tol, w_out, lam_links):
    """One active-set pass of eq. (1) on all three axes: the reactions of the contact nodes
    (targets ``t_c`` (C,3) m) and of the rigid links (node ``link_i`` and its +axis neighbour on
    axis ``link_a``, ``s0`` (L,) m), the positions of ``nodes`` written (Dirichlet nodes at their
    targets; ``xstamp`` = ``version``), ``w_out`` (3,U) the loads on ``uniq``, ``lam_links`` (L,)
    the link reactions (> 0: compressive). Returns (violations (K,2) [node, axis] of springs among
    the nodes marked ``stamp`` below their extreme length by more than ``tol`` x lmin, all finite)."""
    nu = uniq.shape[0]
    nc = contact.shape[0]
    sl = np.empty(nu, dtype=np.int64)
    for p in range(nu):
        sl[p] = slot_of[uniq[p]]
    g = np.empty((nu, nu))
    for p in range(nu):
        for q in range(nu):
            g[q, p] = Gt[sl[p], local[uniq[q]]]
    finite = True
    viol = np.empty((nodes.shape[0] * 3, 2), dtype=np.int64)
    acc = np.empty(nodes.shape[0])
    nv = 0
    for a in range(3):
        nl = 0
        for q in range(link_a.shape[0]):
            if link_a[q] == a:
                nl += 1
        nr = nc + nl
        lq = np.empty(nl, dtype=np.int64)
        ca = np.full(nr, -1, dtype=np.int64)
        cb = np.full(nr, -1, dtype=np.int64)
        sa = np.zeros(nr)
        sb = np.zeros(nr)
        rhs = np.empty(nr)
        for r in range(nc):
            ca[r] = pos_of[contact[r]]
            sa[r] = 1.0
            rhs[r] = t_c[r, a] - v0[local[contact[r]], a]
        r = nc
        for q in range(link_a.shape[0]):
            if link_a[q] != a:
                continue
            lq[r - nc] = q
            i = link_i[q]
            j = nbr[i, 2 * a + 1]
            rhs[r] = -s0[q]
            if not anchor[j]:
                ca[r] = pos_of[j]
                sa[r] = 1.0
                rhs[r] -= v0[local[j], a]
            if not anchor[i]:
                cb[r] = pos_of[i]
                sb[r] = -1.0
                rhs[r] += v0[local[i], a]
            r += 1
        ge = np.zeros((nu, nr))
        for r in range(nr):
            if ca[r] >= 0:
                for p in range(nu):
                    ge[p, r] += sa[r] * g[p, ca[r]]
            if cb[r] >= 0:
                for p in range(nu):
                    ge[p, r] += sb[r] * g[p, cb[r]]
        mm = np.zeros((nr, nr))
        for r in range(nr):
            if ca[r] >= 0:
                for s in range(nr):
                    mm[r, s] += sa[r] * ge[ca[r], s]
            if cb[r] >= 0:
                for s in range(nr):
                    mm[r, s] += sb[r] * ge[cb[r], s]
        lam = np.linalg.solve(mm, rhs) if nr > 0 else np.zeros(0)
        for p in range(nu):
            w_out[a, p] = 0.0
        for r in range(nr):
            if ca[r] >= 0:
                w_out[a, ca[r]] += sa[r] * lam[r]
            if cb[r] >= 0:
                w_out[a, cb[r]] += sb[r] * lam[r]
        for r in range(nl):
            lam_links[lq[r]] = lam[nc + r]
        # positions of the nodes on this axis: one compliance row at a time (streamed, not strided)
        for q in range(nodes.shape[0]):
            i = nodes[q]
            li = local[i]
            acc[q] = rest[i, a] + (v0[li, a] if li >= 0 else 0.0)
        for k in range(nu):
            wk = w_out[a, k]
            row = sl[k]
            for q in range(nodes.shape[0]):
                li = local[nodes[q]]
                if li >= 0:
                    acc[q] += Gt[row, li] * wk
        for q in range(nodes.shape[0]):
            i = nodes[q]
            if fixed[i] or local[i] < 0:
                x[i, a] = fixed_targets[i, a]
            else:
                x[i, a] = acc[q]
                if not np.isfinite(acc[q]):
                    finite = False
            xstamp[i] = version
        # springs of the written region shorter than their extreme length
        d = 2 * a + 1
        for q in range(nodes.shape[0]):
            i = nodes[q]
            j = nbr[i, d]
            if j < 0 or mark[j] != stamp:
                continue
            lm = lmin[i, d]
            if x[j, a] - x[i, a] - lm < -tol * lm:
                viol[nv, 0] = i
                viol[nv, 1] = a
                nv += 1
    return viol[:nv], finite
