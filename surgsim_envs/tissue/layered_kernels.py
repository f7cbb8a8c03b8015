"""numba kernels of the ``layered`` model: constrained local static integration (Lin et al. 2008, eqs. 2.5-2.10).

Arrays (N nodes, 6 NBB directions -x, +x, -y, +y, -z, +z; direction ``d`` has axis ``d // 2`` and
sign ``-1`` for even ``d``; its opposite is ``d ^ 1``):

* ``nbr`` (N,6) int32 neighbour or -1; ``kk`` (N,6) spring constants K_ij (N/m);
* ``lmin`` (N,6) smallest allowed separation (m) along the axis to that neighbour (extreme length);
* ``push`` (N,6) force (N, >= 0) node i passes on to its neighbour in direction d because the spring
  between them is at its extreme length (the force accumulation of eq. 2.5, recomputed at every
  update of i, so a chain of rigid springs passes the force on recursively);
* ``ext`` (N,3) external force g_i (N); ``kc`` (N,) its stiffness -dg/dx (N/m), taken implicitly
  about ``xs`` (the position at the start of the step).

Local equilibrium of node i (eqs. 2.8-2.9): sum_j K_ij [(P_j - P_i) - (P0_j - P0_i)] + g_i + push_in
+ kc_i (xs_i - P_i) = 0, solved for P_i with the neighbours held, then clamped into its neighbouring
bounding box (Fig. 2.11) shrunk by the extreme lengths. Iterated (eq. 2.10) over a work list: a
node whose update moved it more than ``x_tol`` or changed a neighbour's spring force by more than
``f_tol`` puts that neighbour on the list (active nodes); the list empties at equilibrium.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def seed_loaded(ext, kc, fixed, loaded_prev, n_loaded_prev, loaded, queue, n_queue, qstamp, qid):
    """Put every free node with a load (ext != 0 or kc > 0) and every node loaded at the previous
    step on the queue; write the loaded nodes to ``loaded``. Returns (n_loaded, n_queue)."""
    n_loaded = 0
    for i in range(ext.shape[0]):
        if kc[i] > 0.0 or ext[i, 0] != 0.0 or ext[i, 1] != 0.0 or ext[i, 2] != 0.0:
            loaded[n_loaded] = i
            n_loaded += 1
            if not fixed[i] and qstamp[i] != qid:
                qstamp[i] = qid
                queue[n_queue] = i
                n_queue += 1
    for q in range(n_loaded_prev):
        i = loaded_prev[q]
        if not fixed[i] and qstamp[i] != qid:
            qstamp[i] = qid
            queue[n_queue] = i
            n_queue += 1
    return n_loaded, n_queue


@njit(cache=True, nogil=True)
def seed_neighbours(nodes, nbr, fixed, queue, n_queue, qstamp, qid):
    """Queue the free neighbours of ``nodes`` (e.g. Dirichlet nodes that were moved)."""
    for q in range(nodes.shape[0]):
        i = nodes[q]
        if not fixed[i] and qstamp[i] != qid:
            qstamp[i] = qid
            queue[n_queue] = i
            n_queue += 1
        for d in range(6):
            j = nbr[i, d]
            if j >= 0 and not fixed[j] and qstamp[j] != qid:
                qstamp[j] = qid
                queue[n_queue] = j
                n_queue += 1
    return n_queue


@njit(cache=True, nogil=True)
def relax(pos, rest, nbr, kk, lmin, fixed, ext, kc, push, xs, tstamp, step_id, touched, n_touched,
          queue, n_queue, nxt, qstamp, qid, f_tol, x_tol, max_updates, omega):
    """Work-list relaxation (module docstring). Returns (n_touched, n_queue_left, updates, qid, sweeps).

    ``queue[:n_queue]`` holds the active nodes (stamped ``qstamp == qid``); ``touched`` collects the
    nodes updated during step ``step_id`` (their start positions saved in ``xs``). At most
    ``max_updates`` node updates; what is left stays on ``queue`` for the next call. ``omega`` in
    [1, 2) over-relaxes each move (projected SOR; 1 = the paper's plain local solve): the same
    equilibrium, reached in far fewer sweeps.
    """
    updates = 0
    sweeps = 0
    t = np.empty(3)
    while n_queue > 0 and updates < max_updates:
        sweeps += 1
        qid += 1
        m = 0
        for q in range(n_queue):
            i = queue[q]
            if updates >= max_updates or fixed[i]:
                if updates >= max_updates and qstamp[i] != qid:
                    qstamp[i] = qid
                    nxt[m] = i
                    m += 1
                continue
            updates += 1
            if tstamp[i] != step_id:
                tstamp[i] = step_id
                xs[i, 0] = pos[i, 0]
                xs[i, 1] = pos[i, 1]
                xs[i, 2] = pos[i, 2]
                touched[n_touched] = i
                n_touched += 1
            den = kc[i]
            t[0] = ext[i, 0] + kc[i] * xs[i, 0]
            t[1] = ext[i, 1] + kc[i] * xs[i, 1]
            t[2] = ext[i, 2] + kc[i] * xs[i, 2]
            for d in range(6):
                j = nbr[i, d]
                if j < 0:
                    continue
                k = kk[i, d]
                den += k
                for c in range(3):
                    t[c] += k * (pos[j, c] - rest[j, c] + rest[i, c])
                pin = push[j, d ^ 1]
                if pin > 0.0:  # force accumulation from a rigid (extreme) spring: along d ^ 1
                    a = d // 2
                    t[a] += pin if (d ^ 1) & 1 else -pin
            if den <= 0.0:
                continue
            delta2 = 0.0
            for a in range(3):
                target = t[a] / den
                relaxed = pos[i, a] + omega * (target - pos[i, a])
                jm = nbr[i, 2 * a]
                jp = nbr[i, 2 * a + 1]
                lo = -np.inf
                hi = np.inf
                if jm >= 0:
                    lo = pos[jm, a] + lmin[i, 2 * a]
                if jp >= 0:
                    hi = pos[jp, a] - lmin[i, 2 * a + 1]
                new = relaxed
                p_lo = 0.0
                p_hi = 0.0
                if lo > hi:
                    new = 0.5 * (lo + hi)
                    if target < new:
                        p_lo = den * (new - target)
                    else:
                        p_hi = den * (target - new)
                else:
                    if target < lo:
                        p_lo = den * (lo - target)
                    elif target > hi:
                        p_hi = den * (target - hi)
                    if new < lo:
                        new = lo
                    elif new > hi:
                        new = hi
                # pushes changed: the pushed neighbour must re-solve
                if abs(p_lo - push[i, 2 * a]) > f_tol and jm >= 0 and not fixed[jm] and qstamp[jm] != qid:
                    qstamp[jm] = qid
                    nxt[m] = jm
                    m += 1
                if abs(p_hi - push[i, 2 * a + 1]) > f_tol and jp >= 0 and not fixed[jp] and qstamp[jp] != qid:
                    qstamp[jp] = qid
                    nxt[m] = jp
                    m += 1
                push[i, 2 * a] = p_lo
                push[i, 2 * a + 1] = p_hi
                dx = new - pos[i, a]
                delta2 += dx * dx
                pos[i, a] = new
            delta = np.sqrt(delta2)
            if delta > 0.0:
                for d in range(6):
                    j = nbr[i, d]
                    if j < 0 or fixed[j] or qstamp[j] == qid:
                        continue
                    if delta > x_tol or kk[i, d] * delta > f_tol:
                        qstamp[j] = qid
                        nxt[m] = j
                        m += 1
        for q in range(m):
            queue[q] = nxt[q]
        n_queue = m
    return n_touched, n_queue, updates, qid, sweeps


@njit(cache=True, nogil=True)
def spring_forces(pos, rest, nbr, kk, push, nodes, out):
    """Internal force (N) on each of ``nodes``: sum_j K_ij (u_j - u_i) + accumulated pushes (eq. 2.5)."""
    for q in range(nodes.shape[0]):
        i = nodes[q]
        out[q, 0] = 0.0
        out[q, 1] = 0.0
        out[q, 2] = 0.0
        for d in range(6):
            j = nbr[i, d]
            if j < 0:
                continue
            k = kk[i, d]
            for c in range(3):
                out[q, c] += k * ((pos[j, c] - rest[j, c]) - (pos[i, c] - rest[i, c]))
            pin = push[j, d ^ 1]
            if pin > 0.0:
                a = d // 2
                out[q, a] += pin if (d ^ 1) & 1 else -pin


@njit(cache=True, nogil=True)
def elastic_energy(pos, rest, nbr, kk):
    """0.5 sum over springs K |u_j - u_i|^2 (J); each spring counted once."""
    e = 0.0
    for i in range(pos.shape[0]):
        for d in range(1, 6, 2):  # +x, +y, +z: each spring once
            j = nbr[i, d]
            if j < 0:
                continue
            s = 0.0
            for c in range(3):
                du = (pos[j, c] - rest[j, c]) - (pos[i, c] - rest[i, c])
                s += du * du
            e += 0.5 * kk[i, d] * s
    return e
