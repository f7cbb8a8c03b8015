"""Numba kernels of the 3-D fractional tissue model (:mod:`surgsim_envs.tissue.fractional`).

Flat arrays only (no Python objects), so they can later be batched. The displacement history
lives in a double-length ring ``buf`` (2L, 3N): the last ``count`` displacements, newest first,
are rows ``pos .. pos + count - 1``.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def history_sum(buf, pos, count, w, out):
    """out = sum_{k=0}^{count-1} w[k] buf[pos + k] (one row of 3N per past step)."""
    n = out.shape[0]
    for i in range(n):
        out[i] = 0.0
    for k in range(count):
        wk = w[k]
        row = buf[pos + k]
        for i in range(n):
            out[i] += wk * row[i]


@njit(cache=True, nogil=True)
def push(buf, pos, memory, row):
    """Insert ``row`` as the newest entry; returns the new ``pos`` (amortised O(1) per step)."""
    n = buf.shape[1]
    # element loops, not slice assignments: numba's array-to-array assignment builds a shape check
    # whose error message formats the shapes, about 5 s of first-use compile for a copy
    if pos == 0:
        for k in range(memory - 1):                     # buf[memory + 1:] = buf[:memory - 1]
            for i in range(n):
                buf[memory + 1 + k, i] = buf[k, i]
        pos = memory + 1
    pos -= 1
    for i in range(n):
        buf[pos, i] = row[i]
    return pos


@njit(cache=True, nogil=True)
def branch_forces(indptr, indices, a_inf, a_f, d, s, c, out):
    """out = -(K_inf d + c K_f s). Both matrices are stored as 3x3 node blocks on one shared
    block-CSR pattern (indptr, indices over nodes; a_inf, a_f (B, 9) row-major blocks); six
    independent accumulators per node row (no single long dependency chain)."""
    n = indptr.shape[0] - 1
    for i in range(n):
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        b0 = 0.0
        b1 = 0.0
        b2 = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = 3 * indices[p]
            d0, d1, d2 = d[j], d[j + 1], d[j + 2]
            s0, s1, s2 = s[j], s[j + 1], s[j + 2]
            ka = a_inf[p]
            kb = a_f[p]
            a0 += ka[0] * d0 + ka[1] * d1 + ka[2] * d2
            a1 += ka[3] * d0 + ka[4] * d1 + ka[5] * d2
            a2 += ka[6] * d0 + ka[7] * d1 + ka[8] * d2
            b0 += kb[0] * s0 + kb[1] * s1 + kb[2] * s2
            b1 += kb[3] * s0 + kb[4] * s1 + kb[5] * s2
            b2 += kb[6] * s0 + kb[7] * s1 + kb[8] * s2
        out[3 * i] = -(a0 + c * b0)
        out[3 * i + 1] = -(a1 + c * b1)
        out[3 * i + 2] = -(a2 + c * b2)


@njit(cache=True, nogil=True)
def symplectic_step(x, v, rest, buf, pos, count, w, indptr, indices, a_inf, a_f, c, fext, inv_m, alpha, dt,
                    grav, free, remote, d, s, f):
    """One explicit step (semi-implicit Euler, mass damping implicit):

    d = x - X;  s = w_0 d + sum_{k>=1} w_k d_{n-k} + remote;  f = f_ext + m g - (K_inf d + c K_f s);
    v <- (v + dt f / m) / (1 + alpha dt);  x <- x + dt v   (free nodes only; all arrays flat 3N).
    ``d``, ``s``, ``f`` are work arrays (left holding this step's values)."""
    n = x.shape[0]
    for i in range(n):
        d[i] = x[i] - rest[i]
    history_sum(buf, pos, count, w[1:], s)
    w0 = w[0]
    for i in range(n):
        s[i] += w0 * d[i] + remote[i]
    branch_forces(indptr, indices, a_inf, a_f, d, s, c, f)
    for i in range(n):
        node = i // 3
        if free[node]:
            fi = f[i] + fext[i] + grav[i % 3] / inv_m[node]
            v[i] = (v[i] + dt * fi * inv_m[node]) / (1.0 + alpha[node] * dt)
            x[i] += dt * v[i]


@njit(cache=True, nogil=True)
def block_quadratic(indptr, indices, a, d):
    """d^T A d for a 3x3 block-CSR matrix (a (B, 9))."""
    n = indptr.shape[0] - 1
    acc = 0.0
    for i in range(n):
        r0 = 0.0
        r1 = 0.0
        r2 = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            j = 3 * indices[p]
            k = a[p]
            r0 += k[0] * d[j] + k[1] * d[j + 1] + k[2] * d[j + 2]
            r1 += k[3] * d[j] + k[4] * d[j + 1] + k[5] * d[j + 2]
            r2 += k[6] * d[j] + k[7] * d[j + 1] + k[8] * d[j + 2]
        acc += d[3 * i] * r0 + d[3 * i + 1] * r1 + d[3 * i + 2] * r2
    return acc


def csr_pattern(rows: np.ndarray, cols: np.ndarray, n: int):
    """(indptr, indices, slot) of the (node-level) CSR pattern of the (rows, cols) entries;
    ``slot[e]`` is the data position of entry e (duplicates share a slot)."""
    keys = rows.astype(np.int64) * n + cols.astype(np.int64)
    uniq, slot = np.unique(keys, return_inverse=True)
    r = uniq // n
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.add.at(indptr, r + 1, 1)
    return np.cumsum(indptr), (uniq % n).astype(np.int64), slot.reshape(-1)
