"""Numba kernels of the nonlinear viscoelastic mass-spring-damper model (paper 002).

Every spring ``e`` joins nodes ``si[e]`` -> ``sj[e]`` with rest length ``L0[e]`` (m). Its axial
force (N, positive in tension) is

    f_e = K1[e] * dl + K2[e] * dl**3 + s[e]          dl = |x_j - x_i| - L0[e]  (m)

where ``s`` is the force of the spring's Maxwell branch (spring ``kM`` in series with dashpot
``b1``, relaxation time ``tau = b1 / kM``). The branch is integrated exactly for a strain that
varies linearly over the interval ``h`` since it was last committed (one-term Prony recursion):

    s_new = decay * s_old + kMg * (dl_new - dl_old),   decay = exp(-h/tau),
    kMg = kM * (1 - decay) / (h / tau)   (-> kM as h -> 0)

so it is unconditionally stable. All arrays are float64 (SI) except index arrays (int32/int64)
and masks (bool). The kernels do not allocate: callers pass work buffers.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, fastmath=True)
def spring_forces(pos, si, sj, L0, K1, K2, kMg, decay, s_state, dl_state, commit, f_out):
    """Write the spring + Maxwell-branch nodal forces (N) into ``f_out`` (N,3), zeroing it first.

    If ``commit`` the branch state (``s_state``, ``dl_state``) is advanced to ``pos``.
    """
    n = pos.shape[0]
    for a in range(n):
        f_out[a, 0] = 0.0
        f_out[a, 1] = 0.0
        f_out[a, 2] = 0.0
    for e in range(si.shape[0]):
        i = si[e]
        j = sj[e]
        dx = pos[j, 0] - pos[i, 0]
        dy = pos[j, 1] - pos[i, 1]
        dz = pos[j, 2] - pos[i, 2]
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        dl = length - L0[e]
        sb = decay[e] * s_state[e] + kMg[e] * (dl - dl_state[e])
        if commit:
            s_state[e] = sb
            dl_state[e] = dl
        f = K1[e] * dl + K2[e] * dl * dl * dl + sb
        if length > 1e-300:
            c = f / length
            fx = c * dx
            fy = c * dy
            fz = c * dz
            f_out[i, 0] += fx
            f_out[i, 1] += fy
            f_out[i, 2] += fz
            f_out[j, 0] -= fx
            f_out[j, 1] -= fy
            f_out[j, 2] -= fz


@njit(cache=True, fastmath=True)
def symplectic_step(pos, vel, inv_mass, b0, fext, gravity, fixed, dt,
                    si, sj, L0, K1, K2, kMg, decay, s_state, dl_state, f_buf):
    """One semi-implicit (symplectic) Euler step in place:

    v += dt * ((f_spring + f_ext - b0 v) / m + g);  x += dt * v   (fixed nodes untouched).
    """
    spring_forces(pos, si, sj, L0, K1, K2, kMg, decay, s_state, dl_state, True, f_buf)
    g0 = gravity[0]
    g1 = gravity[1]
    g2 = gravity[2]
    for a in range(pos.shape[0]):
        if fixed[a]:
            continue
        im = inv_mass[a]
        b = b0[a]
        v0 = vel[a, 0] + dt * ((f_buf[a, 0] + fext[a, 0] - b * vel[a, 0]) * im + g0)
        v1 = vel[a, 1] + dt * ((f_buf[a, 1] + fext[a, 1] - b * vel[a, 1]) * im + g1)
        v2 = vel[a, 2] + dt * ((f_buf[a, 2] + fext[a, 2] - b * vel[a, 2]) * im + g2)
        vel[a, 0] = v0
        vel[a, 1] = v1
        vel[a, 2] = v2
        pos[a, 0] += dt * v0
        pos[a, 1] += dt * v1
        pos[a, 2] += dt * v2


@njit(cache=True, fastmath=True)
def branch_forces(pos, si, sj, L0, kMg, decay, s_state, dl_state, out):
    """Maxwell-branch force (N) of each spring at ``pos`` without committing the state."""
    for e in range(si.shape[0]):
        i = si[e]
        j = sj[e]
        dx = pos[j, 0] - pos[i, 0]
        dy = pos[j, 1] - pos[i, 1]
        dz = pos[j, 2] - pos[i, 2]
        dl = math.sqrt(dx * dx + dy * dy + dz * dz) - L0[e]
        out[e] = decay[e] * s_state[e] + kMg[e] * (dl - dl_state[e])


@njit(cache=True, fastmath=True)
def spring_tangents(pos, si, sj, L0, K1, K2, kMg, s_branch, clamp, coef_a, coef_g, unit):
    """Per-spring tangent stiffness block ``K_e = a u u^T + g I`` (N/m) at ``pos``, with the
    Maxwell branches carrying force ``s_branch`` and stiffness ``kMg`` over the coming step.

    a = df/dl - g, g = f / l (clamped at >= 0 if ``clamp`` so that K_e is positive semi-definite).
    """
    for e in range(si.shape[0]):
        i = si[e]
        j = sj[e]
        dx = pos[j, 0] - pos[i, 0]
        dy = pos[j, 1] - pos[i, 1]
        dz = pos[j, 2] - pos[i, 2]
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        if length < 1e-300:
            length = 1e-300
        dl = length - L0[e]
        f = K1[e] * dl + K2[e] * dl * dl * dl + s_branch[e]
        dfdl = K1[e] + 3.0 * K2[e] * dl * dl + kMg[e]
        g = f / length
        if clamp and g < 0.0:
            g = 0.0
        coef_a[e] = dfdl - g
        coef_g[e] = g
        unit[e, 0] = dx / length
        unit[e, 1] = dy / length
        unit[e, 2] = dz / length


@njit(cache=True, fastmath=True)
def _system_matvec(x, diag_m, h2, si, sj, coef_a, coef_g, unit, fixed, out):
    """out = (diag_m + h2 * K) x with fixed rows/cols removed."""
    n = x.shape[0]
    for a in range(n):
        d = diag_m[a]
        out[a, 0] = d * x[a, 0]
        out[a, 1] = d * x[a, 1]
        out[a, 2] = d * x[a, 2]
    for e in range(si.shape[0]):
        i = si[e]
        j = sj[e]
        d0 = x[i, 0] - x[j, 0]
        d1 = x[i, 1] - x[j, 1]
        d2 = x[i, 2] - x[j, 2]
        u0 = unit[e, 0]
        u1 = unit[e, 1]
        u2 = unit[e, 2]
        t = coef_a[e] * (u0 * d0 + u1 * d1 + u2 * d2)
        g = coef_g[e]
        y0 = h2 * (t * u0 + g * d0)
        y1 = h2 * (t * u1 + g * d1)
        y2 = h2 * (t * u2 + g * d2)
        out[i, 0] += y0
        out[i, 1] += y1
        out[i, 2] += y2
        out[j, 0] -= y0
        out[j, 1] -= y1
        out[j, 2] -= y2
    for a in range(n):
        if fixed[a]:
            out[a, 0] = 0.0
            out[a, 1] = 0.0
            out[a, 2] = 0.0


@njit(cache=True, fastmath=True)
def implicit_step(pos, vel, mass, b0, fext, gravity, fixed, kc, dt,
                  si, sj, L0, K1, K2, kMg, decay, kMg_next, s_state, dl_state,
                  f_buf, coef_a, coef_g, unit, diag_m, precond, r, z, p, ap, tol, max_iter):
    """One linearly implicit backward-Euler step (one Newton step) in place.

    Solves (M + dt B + dt^2 (K + Kc)) v_new = M v + dt (f(x) + f_ext + M g) by Jacobi-
    preconditioned conjugate gradients (matrix-free), then x += dt * v_new. K is the spring
    tangent (Maxwell branch included through kMg), B = diag(b0), Kc = diag(kc) the external
    contact stiffness. ``kMg``/``decay`` bring the Maxwell branches from their last commit up to
    ``pos``; ``kMg_next`` is the branches' stiffness over this step of length ``dt``.
    Returns the number of CG iterations.
    """
    n = pos.shape[0]
    # branch state is committed at x_n; tangents at x_n with the branch's stiffness over the coming step
    spring_forces(pos, si, sj, L0, K1, K2, kMg, decay, s_state, dl_state, True, f_buf)
    spring_tangents(pos, si, sj, L0, K1, K2, kMg_next, s_state, True, coef_a, coef_g, unit)
    h2 = dt * dt
    for a in range(n):
        diag_m[a] = mass[a] + dt * b0[a] + h2 * kc[a]
    # Jacobi preconditioner: diagonal of the system matrix
    for a in range(n):
        precond[a, 0] = diag_m[a]
        precond[a, 1] = diag_m[a]
        precond[a, 2] = diag_m[a]
    for e in range(si.shape[0]):
        i = si[e]
        j = sj[e]
        for c in range(3):
            d = h2 * (coef_a[e] * unit[e, c] * unit[e, c] + coef_g[e])
            precond[i, c] += d
            precond[j, c] += d
    # right-hand side into z, residual r = rhs - A v
    rhs_norm2 = 0.0
    for a in range(n):
        for c in range(3):
            if fixed[a]:
                z[a, c] = 0.0
                vel[a, c] = 0.0
            else:
                z[a, c] = mass[a] * vel[a, c] + dt * (f_buf[a, c] + fext[a, c] + mass[a] * gravity[c])
                rhs_norm2 += z[a, c] * z[a, c]
    _system_matvec(vel, diag_m, h2, si, sj, coef_a, coef_g, unit, fixed, ap)
    rz = 0.0
    r_norm2 = 0.0
    for a in range(n):
        for c in range(3):
            rv = z[a, c] - ap[a, c]
            r[a, c] = rv
            zv = rv / precond[a, c]
            z[a, c] = zv
            p[a, c] = zv
            rz += rv * zv
            r_norm2 += rv * rv
    limit = tol * tol * rhs_norm2
    it = 0
    while it < max_iter and r_norm2 > limit and r_norm2 > 1e-300:
        _system_matvec(p, diag_m, h2, si, sj, coef_a, coef_g, unit, fixed, ap)
        pap = 0.0
        for a in range(n):
            pap += p[a, 0] * ap[a, 0] + p[a, 1] * ap[a, 1] + p[a, 2] * ap[a, 2]
        if not (pap > 0.0):
            break
        alpha = rz / pap
        rz_new = 0.0
        r_norm2 = 0.0
        for a in range(n):
            for c in range(3):
                vel[a, c] += alpha * p[a, c]
                rv = r[a, c] - alpha * ap[a, c]
                r[a, c] = rv
                zv = rv / precond[a, c]
                z[a, c] = zv
                rz_new += rv * zv
                r_norm2 += rv * rv
        beta = rz_new / rz
        rz = rz_new
        for a in range(n):
            for c in range(3):
                p[a, c] = z[a, c] + beta * p[a, c]
        it += 1
    for a in range(n):
        if fixed[a]:
            continue
        pos[a, 0] += dt * vel[a, 0]
        pos[a, 1] += dt * vel[a, 1]
        pos[a, 2] += dt * vel[a, 2]
    return it


@njit(cache=True, fastmath=True)
def elastic_energy(pos, si, sj, L0, K1, K2, kM, kMg, decay, s_state, dl_state):
    """Energy (J) stored in the springs, sum 0.5 K1 dl^2 + 0.25 K2 dl^4, plus the Maxwell
    springs, sum s^2 / (2 kM) (branch force taken at ``pos``)."""
    energy = 0.0
    for e in range(si.shape[0]):
        i = si[e]
        j = sj[e]
        dx = pos[j, 0] - pos[i, 0]
        dy = pos[j, 1] - pos[i, 1]
        dz = pos[j, 2] - pos[i, 2]
        dl = math.sqrt(dx * dx + dy * dy + dz * dz) - L0[e]
        d2 = dl * dl
        energy += 0.5 * K1[e] * d2 + 0.25 * K2[e] * d2 * d2
        if kM[e] > 0.0:
            sb = decay[e] * s_state[e] + kMg[e] * (dl - dl_state[e])
            energy += 0.5 * sb * sb / kM[e]
    return energy


@njit(cache=True, fastmath=True)
def gershgorin_lambda_max(pos, inv_mass, si, sj, L0, K1, K2, kM, s_state, dl_state, decay, kMg):
    """Upper bound (1/s^2) of the largest eigenvalue of M^-1 K_tangent (row-sum norm).

    Uses the instantaneous Maxwell stiffness kM (the stiffest the branch can be) and the
    tension part of the geometric stiffness.
    """
    n = pos.shape[0]
    rows = np.zeros((n, 3))
    for e in range(si.shape[0]):
        i = si[e]
        j = sj[e]
        dx = pos[j, 0] - pos[i, 0]
        dy = pos[j, 1] - pos[i, 1]
        dz = pos[j, 2] - pos[i, 2]
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        if length < 1e-300:
            length = 1e-300
        dl = length - L0[e]
        sb = decay[e] * s_state[e] + kMg[e] * (dl - dl_state[e])
        f = K1[e] * dl + K2[e] * dl * dl * dl + sb
        dfdl = K1[e] + 3.0 * K2[e] * dl * dl + kM[e]
        g = f / length
        if g < 0.0:
            g = 0.0
        a = abs(dfdl - g)
        u0 = abs(dx) / length
        u1 = abs(dy) / length
        u2 = abs(dz) / length
        s1 = u0 + u1 + u2
        # diagonal block and off-diagonal block contribute equally
        r0 = 2.0 * (a * u0 * s1 + g)
        r1 = 2.0 * (a * u1 * s1 + g)
        r2 = 2.0 * (a * u2 * s1 + g)
        rows[i, 0] += r0
        rows[i, 1] += r1
        rows[i, 2] += r2
        rows[j, 0] += r0
        rows[j, 1] += r1
        rows[j, 2] += r2
    best = 0.0
    for a in range(n):
        for c in range(3):
            v = rows[a, c] * inv_mass[a]
            if v > best:
                best = v
    return best
