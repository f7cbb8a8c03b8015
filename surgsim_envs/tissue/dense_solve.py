"""A small dense linear solve for numba kernels: Gaussian elimination with partial pivoting.

``np.linalg.solve`` inside a numba kernel calls LAPACK's ``dgesv``, and numba builds its
wrapper (copies into Fortran order, shape checks whose error messages format the shapes) on
first use: about 8 s of compile on a 2-core host, paid by every fresh process that steps a
kernel holding one. The contact systems solved per step are small (3 x the loaded nodes) and
well conditioned (``I + W k``, W symmetric positive definite, k >= 0), where plain elimination
with partial pivoting is as accurate and compiles in well under a second. Without fast-math
its arithmetic is fixed IEEE operations in a fixed order, so it gives the same bits on every
x86-64 CPU, where OpenBLAS's LAPACK picks kernels by CPU.
"""

from __future__ import annotations

from numba import njit


@njit(cache=True, error_model="numpy")
def solve_dense(a, b):
    """x (n,) with ``a x = b`` for a dense (n, n) ``a`` and (n,) ``b`` (both left unchanged): Gaussian
    elimination with partial pivoting, then back substitution. Raises ValueError on a zero pivot
    (a singular matrix)."""
    n = a.shape[0]
    m = a.copy()
    x = b.copy()
    for k in range(n):
        p = k
        big = abs(m[k, k])
        for i in range(k + 1, n):
            v = abs(m[i, k])
            if v > big:
                big = v
                p = i
        if big == 0.0:
            raise ValueError("solve_dense: the matrix is singular (a zero pivot)")
        if p != k:
            for j in range(k, n):
                t = m[k, j]
                m[k, j] = m[p, j]
                m[p, j] = t
            t = x[k]
            x[k] = x[p]
            x[p] = t
        piv = m[k, k]
        for i in range(k + 1, n):
            f = m[i, k] / piv
            if f != 0.0:
                for j in range(k + 1, n):
                    m[i, j] -= f * m[k, j]
                x[i] -= f * x[k]
    for i in range(n - 1, -1, -1):
        s = x[i]
        for j in range(i + 1, n):
            s -= m[i, j] * x[j]
        x[i] = s / m[i, i]
    return x
