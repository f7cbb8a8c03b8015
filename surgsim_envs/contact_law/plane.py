"""The contact law of one quasi-static step on the contacts' tangent planes: the data a contact
model hands a tissue step that solves it exactly instead of linearising it, and the law's own
evaluation and per-pair solution. Both the contact layer (which builds it,
:mod:`surgsim_envs.contact.plane_law`) and the tissue layer (which solves it,
:mod:`surgsim_envs.tissue.condensed_plane_solve`) import it; it imports neither.

A quasi-static step that linearises the contact force about where it starts, ``g = f - k (x - x^n)``
with one isotropic stiffness ``k`` per node, holds a sliding node back tangentially with the
normal penalty ``k_n``, and caps its friction with the penalty where the step starts, which
carries the tool's travel over the step (docs/contact.md, "Friction in a quasi-static step"). The
plane law keeps each contact pair's own law over the step instead, with the geometry frozen on the
pair's tangent plane at the linearisation point ``x^n`` (node ``i``, unit normal ``n``, displacement
``d = x - x^n``):

    f_n(d) = max(0, f_n0 - k_n n . d)                      normal force (penalty, unilateral), N
    s(d)   = P (t0 + d),   P = I - n n^T                   stick spring's stretch, m
    stick:  f_t = -k_t s                  while |k_t s| <= mu_c f_n
    slide:  f_t = -mu f_n s / |s|         otherwise (kinetic cap, along the stretch)
    F(d)   = f_n(d) n + f_t(d)

``f_n0`` is the penalty at ``x^n`` (with the tool's side of the contact damping), ``k_n`` the normal
stiffness (plus c_n / dt on a point that approaches, with implicit damping), ``t0`` the stretch at
``x^n`` from the stick anchor the pair had before the step (zero for a new contact), ``mu_c`` the
cap a sticking contact holds (``mu_s``, or ``mu`` for one that was sliding), ``k_t`` the stick
spring. This is :mod:`surgsim_envs.contact.friction`'s law with the anchor from before the step,
evaluated where the step ends: the return mapping of an implicit step. The contact kernel's call at
``x^n`` gives the same force at d = 0.

:func:`solve_pair` solves one pair's law against a local compliance: ``d = d0 + A F`` with ``A``
(3x3, m/N) the compliance of the pair's node and ``d0`` its displacement with the pair's force
removed. A tissue model with the capability ``plane_contact_law`` sweeps it over the pairs (a
nonlinear block Gauss-Seidel on its condensed compliance). Nodes only: surface samples spread a
force over three nodes and are not supported. A slide is solved where ``1 + k_n n^T a (n - mu s) > 0``:
the compliance's coupling of a tangential load into the normal displacement, times mu, stays below
its normal compliance (plus 1 / k_n). On a tissue surface the coupling is a fraction of the normal
compliance ((1 - 2 nu) / (2 (1 - nu)) for a half-space, 0.09 at nu 0.45); past that bound the
slide would lock (its normal force grows without limit) and the pair takes the stick trial's force
capped at the cone. Units: m, N, N/m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

#: the fields of one pair in :class:`PlaneContactLaw`'s ``data`` rows
NORMAL, KN, FN0, STRETCH, KT, MU, MU_CAP, F0 = 0, 3, 4, 5, 8, 9, 10, 11
#: columns of a ``data`` row
ROW = 14
#: secant iterations on the slide direction from the stick trial's (:func:`solve_pair`)
SECANT_ITERATIONS = 12
#: slide directions sampled around the tangent plane, then bisected, where the secant fails
SLIDE_SAMPLES = 32


@dataclass
class PlaneContactLaw:
    """The pairs of one step's plane law (module docstring), arrays owned by the
    contact model and overwritten by the next build.

    nodes: (P,) int64, each pair's tissue node. data: (P, ROW) float64, per pair: unit normal (3),
    k_n (N/m), f_n0 (N), t0 (3, m), k_t (N/m), mu, mu_c, and the pair's force at d = 0 (3, N).
    count: P, the number of pairs (the arrays may be longer).
    """

    nodes: np.ndarray
    data: np.ndarray
    count: int = 0


@njit(cache=True, nogil=True, inline="always")
def _stick_force(row, d0, d1, d2, out):
    """The stick force of pair ``row`` at displacement d: (f_n(d), written to out (3))."""
    n0, n1, n2 = row[0], row[1], row[2]
    fn = row[FN0] - row[KN] * (n0 * d0 + n1 * d1 + n2 * d2)
    s0, s1, s2 = row[5] + d0, row[6] + d1, row[7] + d2
    sn = s0 * n0 + s1 * n1 + s2 * n2
    s0, s1, s2 = s0 - sn * n0, s1 - sn * n1, s2 - sn * n2
    kt = row[KT]
    out[0] = fn * n0 - kt * s0
    out[1] = fn * n1 - kt * s1
    out[2] = fn * n2 - kt * s2
    return fn


@njit(cache=True, nogil=True)
def pair_force(row, d0, d1, d2, out):
    """The plane law's force F(d) (N) of the pair with data ``row`` at displacement (d0, d1, d2) m,
    written to ``out`` (3); returns the normal force f_n >= 0."""
    n0, n1, n2 = row[0], row[1], row[2]
    fn = row[FN0] - row[KN] * (n0 * d0 + n1 * d1 + n2 * d2)
    if fn <= 0.0:
        out[0] = out[1] = out[2] = 0.0
        return 0.0
    s0, s1, s2 = row[5] + d0, row[6] + d1, row[7] + d2
    sn = s0 * n0 + s1 * n1 + s2 * n2
    s0, s1, s2 = s0 - sn * n0, s1 - sn * n1, s2 - sn * n2
    sl = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    kt = row[KT]
    if kt * sl <= row[MU_CAP] * fn:
        c = kt
    else:
        c = row[MU] * fn / sl
    out[0] = fn * n0 - c * s0
    out[1] = fn * n1 - c * s1
    out[2] = fn * n2 - c * s2
    return fn


@njit(cache=True, nogil=True)
def _solve3(a, b, out):
    """out = a^-1 b for a 3x3 ``a`` (Cramer's rule); returns False if ``a`` is singular."""
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
    if det == 0.0 or not math.isfinite(det):
        return False
    inv = 1.0 / det
    c10 = a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]
    c11 = a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]
    c12 = a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]
    c20 = a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]
    c21 = a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]
    c22 = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    out[0] = (c00 * b[0] + c10 * b[1] + c20 * b[2]) * inv
    out[1] = (c01 * b[0] + c11 * b[1] + c21 * b[2]) * inv
    out[2] = (c02 * b[0] + c12 * b[1] + c22 * b[2]) * inv
    return True


@njit(cache=True, nogil=True, inline="always")
def _slide_normal(row, a, d0, s0, s1, s2):
    """The normal force (N) of a pair sliding along the unit stretch direction s against the
    compliance ``a`` (3,3) from ``d0`` (3): f_n = f_n(d0) / (1 + k_n n^T a (n - mu s))."""
    n0, n1, n2 = row[0], row[1], row[2]
    mu, kn = row[MU], row[KN]
    v0, v1, v2 = n0 - mu * s0, n1 - mu * s1, n2 - mu * s2
    den = 1.0 + kn * (n0 * (a[0, 0] * v0 + a[0, 1] * v1 + a[0, 2] * v2)
                      + n1 * (a[1, 0] * v0 + a[1, 1] * v1 + a[1, 2] * v2)
                      + n2 * (a[2, 0] * v0 + a[2, 1] * v1 + a[2, 2] * v2))
    if not (den > 0.0):
        return -1.0
    return (row[FN0] - kn * (n0 * d0[0] + n1 * d0[1] + n2 * d0[2])) / den


@njit(cache=True, nogil=True)
def _slide_residual(row, a, d0, th, b1x, b1y, b1z, b2x, b2y, b2z):
    """For the slide direction s(th) = cos(th) b1 + sin(th) b2: the stretch it leads to, projected
    on the direction across s (zero at a consistent slide) and along s (positive there)."""
    n0, n1, n2 = row[0], row[1], row[2]
    c, sn = math.cos(th), math.sin(th)
    s0, s1, s2 = c * b1x + sn * b2x, c * b1y + sn * b2y, c * b1z + sn * b2z
    q0, q1, q2 = -sn * b1x + c * b2x, -sn * b1y + c * b2y, -sn * b1z + c * b2z
    fn = _slide_normal(row, a, d0, s0, s1, s2)
    mu = row[MU]
    v0, v1, v2 = fn * (n0 - mu * s0), fn * (n1 - mu * s1), fn * (n2 - mu * s2)
    e0 = row[5] + d0[0] + a[0, 0] * v0 + a[0, 1] * v1 + a[0, 2] * v2
    e1 = row[6] + d0[1] + a[1, 0] * v0 + a[1, 1] * v1 + a[1, 2] * v2
    e2 = row[7] + d0[2] + a[2, 0] * v0 + a[2, 1] * v1 + a[2, 2] * v2
    return e0 * q0 + e1 * q1 + e2 * q2, e0 * s0 + e1 * s1 + e2 * s2


@njit(cache=True, nogil=True)
def solve_pair(row, a, d0, out, work):
    """The pair's force F (N, written to ``out`` (3)) that satisfies its plane law at the
    displacement ``d = d0 + a F`` (``a`` (3,3) m/N, the node's own compliance; ``d0`` (3,) m, its
    displacement without this pair's force). ``work``: (5, 3) scratch. Tries, in order, the open
    contact (F = 0 where f_n(d0) <= 0), sticking (linear), and sliding (its direction the root of
    the stretch's component across it: secant steps from the stick trial's direction, else
    ``SLIDE_SAMPLES`` directions around the plane, bisected). Returns 0 open, 1 stick, 2 slide."""
    n0, n1, n2 = row[0], row[1], row[2]
    kn, kt = row[KN], row[KT]
    if row[FN0] - kn * (n0 * d0[0] + n1 * d0[1] + n2 * d0[2]) <= 0.0:
        out[0] = out[1] = out[2] = 0.0
        return 0
    # stick: F = Fc - K d, K = kn n n^T + kt P; (I + K a) F = Fc - K d0
    nv = (n0, n1, n2)
    ka = work[0:3]
    for r in range(3):
        for q in range(3):
            k0 = kn * nv[r] * nv[0] + kt * ((1.0 if r == 0 else 0.0) - nv[r] * nv[0])
            k1 = kn * nv[r] * nv[1] + kt * ((1.0 if r == 1 else 0.0) - nv[r] * nv[1])
            k2 = kn * nv[r] * nv[2] + kt * ((1.0 if r == 2 else 0.0) - nv[r] * nv[2])
            ka[r, q] = (1.0 if r == q else 0.0) + k0 * a[0, q] + k1 * a[1, q] + k2 * a[2, q]
    f0 = work[3]
    _stick_force(row, d0[0], d0[1], d0[2], f0)        # Fc - K d0
    f = work[4]
    if _solve3(ka, f0, f):
        fn = f[0] * n0 + f[1] * n1 + f[2] * n2
        t0, t1, t2 = f[0] - fn * n0, f[1] - fn * n1, f[2] - fn * n2
        tl = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        if fn > 0.0 and tl <= row[MU_CAP] * fn:
            out[0], out[1], out[2] = f[0], f[1], f[2]
            return 1
        if tl > 0.0:                              # the stretch points against the stick force
            s0, s1, s2 = -t0 / tl, -t1 / tl, -t2 / tl
        else:
            s0, s1, s2 = 0.0, 0.0, 0.0
    else:
        s0, s1, s2 = 0.0, 0.0, 0.0
        f[0] = f[1] = f[2] = 0.0
    if s0 == 0.0 and s1 == 0.0 and s2 == 0.0:     # a stretch direction from the unloaded displacement
        e0, e1, e2 = row[5] + d0[0], row[6] + d0[1], row[7] + d0[2]
        en = e0 * n0 + e1 * n1 + e2 * n2
        s0, s1, s2 = e0 - en * n0, e1 - en * n1, e2 - en * n2
        sl = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
        if sl == 0.0:
            out[0] = out[1] = out[2] = 0.0
            return 0
        s0, s1, s2 = s0 / sl, s1 / sl, s2 / sl
    # slide: F = f_n (n - mu s) with s the unit stretch P (t0 + d0 + a F); s = cos(th) b1 + sin(th) b2
    # solves h(th) = stretch . s_perp = 0 with stretch . s > 0 (sampled, then bisected)
    b1x, b1y, b1z = s0, s1, s2                     # the stick trial's stretch direction starts the basis
    b2x, b2y, b2z = n1 * b1z - n2 * b1y, n2 * b1x - n0 * b1z, n0 * b1y - n1 * b1x
    best_th, best_gap, found = 0.0, 1e300, False
    # secant iterations from the stick trial's direction (th = 0) first: the usual case, a few calls
    t0_, t1_ = 0.0, 1e-3
    h0, p0 = _slide_residual(row, a, d0, t0_, b1x, b1y, b1z, b2x, b2y, b2z)
    h1, p1 = _slide_residual(row, a, d0, t1_, b1x, b1y, b1z, b2x, b2y, b2z)
    for _ in range(SECANT_ITERATIONS):
        if h1 == h0:
            break
        t2_ = t1_ - h1 * (t1_ - t0_) / (h1 - h0)
        if not (abs(t2_) < math.pi):
            break
        t0_, h0 = t1_, h1
        t1_ = t2_
        h1, p1 = _slide_residual(row, a, d0, t1_, b1x, b1y, b1z, b2x, b2y, b2z)
        if abs(t1_ - t0_) < 1e-13:
            break
    scale = math.sqrt((row[5] + d0[0]) ** 2 + (row[6] + d0[1]) ** 2 + (row[7] + d0[2]) ** 2) + 1e-300
    if p1 > 0.0 and abs(h1) <= 1e-12 * max(scale, p1):
        best_th, found = t1_, True
    h_prev, par_prev, th_prev = 0.0, 0.0, 0.0
    for k in range(0 if found else SLIDE_SAMPLES + 1):
        th = 2.0 * math.pi * k / SLIDE_SAMPLES
        h, par = _slide_residual(row, a, d0, th, b1x, b1y, b1z, b2x, b2y, b2z)
        if k > 0 and (h_prev <= 0.0) != (h <= 0.0) and (par > 0.0 or par_prev > 0.0):
            lo, hi, hlo = th_prev, th, h_prev
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                hm, _pm = _slide_residual(row, a, d0, mid, b1x, b1y, b1z, b2x, b2y, b2z)
                if (hm <= 0.0) == (hlo <= 0.0):
                    lo, hlo = mid, hm
                else:
                    hi = mid
            root = 0.5 * (lo + hi)
            _h, pr = _slide_residual(row, a, d0, root, b1x, b1y, b1z, b2x, b2y, b2z)
            gap = min(root, 2.0 * math.pi - root)   # the root nearest the stick trial's direction
            if pr > 0.0 and gap < best_gap:
                best_th, best_gap, found = root, gap, True
        h_prev, par_prev, th_prev = h, par, th
    if not found:                                  # no consistent slide: the stick trial's direction
        best_th = 0.0
    c, sn = math.cos(best_th), math.sin(best_th)
    s0, s1, s2 = c * b1x + sn * b2x, c * b1y + sn * b2y, c * b1z + sn * b2z
    mu = row[MU]
    fn = _slide_normal(row, a, d0, s0, s1, s2)
    if fn <= 0.0:
        if fn < 0.0:       # the compliance locks the slide (module docstring): the stick trial, capped
            fn = f[0] * n0 + f[1] * n1 + f[2] * n2
            if fn > 0.0:
                out[0] = fn * (n0 - mu * s0)
                out[1] = fn * (n1 - mu * s1)
                out[2] = fn * (n2 - mu * s2)
                return 2
        out[0] = out[1] = out[2] = 0.0
        return 0
    out[0] = fn * (n0 - mu * s0)
    out[1] = fn * (n1 - mu * s1)
    out[2] = fn * (n2 - mu * s2)
    return 2


__all__ = ["F0", "FN0", "KN", "KT", "MU", "MU_CAP", "PlaneContactLaw", "ROW", "pair_force", "solve_pair"]
