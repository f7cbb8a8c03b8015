"""Numba kernels of the averaged-nodal-volume term of the calibrated mass-spring model.

Each node i owns the volume V_i = sum over its tets of V_t / 4 (V_t signed, m^3) and stores

    E_i = 0.5 kv_i (V_i - V0_i)^2 / V0_i          (J; kv_i in Pa)

Forces: with p_i = kv_i (V_i - V0_i) / V0_i (Pa), ``f_a = -sum_t (sum_{i in t} p_i / 4) dV_t/dx_a``
(Bonet & Burton 1998 averaged nodal pressure, the volumetric part of ``fem``'s ANP). Gauss-Newton
tangent: ``K = sum_i c_i G_i G_i^T``, c_i = kv_i / V0_i, G_i = dV_i/dx = sum_{t ∋ i} (dV_t/dx) / 4;
the product K x is two passes over the tets (s_i = G_i . x, then scatter). The indefinite
``p_i d2V_i/dx2`` part is left out (zero at rest), as in the per-tet term of
:mod:`surgsim_envs.tissue.msd_kernels`. :func:`implicit_step` is that module's backward-Euler
step (springs + Maxwell branches) with this term in place of the per-tet one.
"""

from __future__ import annotations

import numpy as np
from numba import njit, uint64

from surgsim_envs.tissue.msd_kernels import (_system_matvec, _tet_volume_gradient, spring_forces, spring_tangents,
                                             symplectic_step_work)


@njit(cache=True, fastmath=True)
def node_volumes(pos, tets, out):
    """out[i] = sum over the tets of node i of V_t / 4 (m^3) at ``pos``."""
    g = np.empty((4, 3))
    out[:] = 0.0
    for t in range(tets.shape[0]):
        q = 0.25 * _tet_volume_gradient(pos, tets, t, g)
        for a in range(4):
            out[tets[t, a]] += q


@njit(cache=True, fastmath=True, error_model="numpy", nogil=True)
def add_forces(pos, tets, V0, kv, vbuf, f_out):
    """Add the nodal-volume forces (N) to ``f_out`` (N,3); ``vbuf`` (N,) is work space.

    Two passes over the tets, written out with scalar locals: the volumes (a triple product per
    tet), then each tet's gradient recomputed and scattered with its mean nodal pressure (recomputing
    3 cross products is cheaper than storing and re-reading a (T,4,3) gradient array: 92 vs 120 us
    for the 6,144-tet palpation slab; structure-of-arrays passes were no faster either). Node indices
    are read as unsigned: numba then emits no negative-index wrap-around per access (the tets are
    valid, non-negative node ids): 23 vs 33 us on the 1,200-tet Palpation slab, the same forces bit for bit
    (CHANGELOG.md "Calibrated mass-spring: compiled \"auto\", selective mass scaling")."""
    vbuf[:] = 0.0
    for t in range(tets.shape[0]):
        a = uint64(tets[t, 0])
        b = uint64(tets[t, 1])
        c = uint64(tets[t, 2])
        d = uint64(tets[t, 3])
        ax = pos[a, 0]
        ay = pos[a, 1]
        az = pos[a, 2]
        e10 = pos[b, 0] - ax
        e11 = pos[b, 1] - ay
        e12 = pos[b, 2] - az
        e20 = pos[c, 0] - ax
        e21 = pos[c, 1] - ay
        e22 = pos[c, 2] - az
        e30 = pos[d, 0] - ax
        e31 = pos[d, 1] - ay
        e32 = pos[d, 2] - az
        q = (e10 * (e21 * e32 - e22 * e31) + e11 * (e22 * e30 - e20 * e32) + e12 * (e20 * e31 - e21 * e30)) / 24.0
        vbuf[a] += q
        vbuf[b] += q
        vbuf[c] += q
        vbuf[d] += q
    for i in range(vbuf.shape[0]):
        vbuf[i] = kv[i] * (vbuf[i] - V0[i]) / V0[i]        # pressure p_i (Pa)
    for t in range(tets.shape[0]):
        a = uint64(tets[t, 0])
        b = uint64(tets[t, 1])
        c = uint64(tets[t, 2])
        d = uint64(tets[t, 3])
        p = (vbuf[a] + vbuf[b] + vbuf[c] + vbuf[d]) * (0.25 / 6.0)
        ax = pos[a, 0]
        ay = pos[a, 1]
        az = pos[a, 2]
        e10 = pos[b, 0] - ax
        e11 = pos[b, 1] - ay
        e12 = pos[b, 2] - az
        e20 = pos[c, 0] - ax
        e21 = pos[c, 1] - ay
        e22 = pos[c, 2] - az
        e30 = pos[d, 0] - ax
        e31 = pos[d, 1] - ay
        e32 = pos[d, 2] - az
        g10 = e21 * e32 - e22 * e31      # 6 dV/dx_b, 6 dV/dx_c, 6 dV/dx_d; dV/dx_a = -(sum)
        g11 = e22 * e30 - e20 * e32
        g12 = e20 * e31 - e21 * e30
        g20 = e31 * e12 - e32 * e11
        g21 = e32 * e10 - e30 * e12
        g22 = e30 * e11 - e31 * e10
        g30 = e11 * e22 - e12 * e21
        g31 = e12 * e20 - e10 * e22
        g32 = e10 * e21 - e11 * e20
        f_out[b, 0] -= p * g10
        f_out[b, 1] -= p * g11
        f_out[b, 2] -= p * g12
        f_out[c, 0] -= p * g20
        f_out[c, 1] -= p * g21
        f_out[c, 2] -= p * g22
        f_out[d, 0] -= p * g30
        f_out[d, 1] -= p * g31
        f_out[d, 2] -= p * g32
        f_out[a, 0] += p * (g10 + g20 + g30)
        f_out[a, 1] += p * (g11 + g21 + g31)
        f_out[a, 2] += p * (g12 + g22 + g32)


def gradient_pattern(tets: np.ndarray, n_nodes: int):
    """Sparsity of the nodal volume gradients G_i = dV_i/dx (row i: the nodes a of node i's tets), built
    once per mesh: ``(indptr (N+1,), cols (nnz,), slot (T,4,4))`` with slot[t, p, q] the entry
    (row tets[t,p], col tets[t,q])."""
    tets = np.asarray(tets, dtype=np.int64)
    rows = np.repeat(tets, 4, axis=1).ravel()
    cols = np.tile(tets, (1, 4)).ravel()
    uniq, inv = np.unique(rows * n_nodes + cols, return_inverse=True)
    indptr = np.searchsorted(uniq // n_nodes, np.arange(n_nodes + 1)).astype(np.int64)
    return (indptr, np.ascontiguousarray(uniq % n_nodes, dtype=np.int64),
            np.ascontiguousarray(inv.reshape(len(tets), 4, 4), dtype=np.int64))


@njit(cache=True, fastmath=True, error_model="numpy")
def lambda_bound(pos, tets, slot, indptr, cols, c, inv_mass, fixed, G, gi):
    """Cauchy-Schwarz bound (1/s^2) of the largest eigenvalue of M^-1 K_v (see
    ``CalibratedMassSpringModel.volume_lambda_bound``): G (nnz,3) and gi (N,) are work space.
    Indices read as unsigned (no wrap-around code per access, as in :func:`add_forces`)."""
    G[:, :] = 0.0
    g = np.empty((4, 3))
    for t in range(tets.shape[0]):
        _tet_volume_gradient(pos, tets, t, g)
        for q in range(4):
            gx = 0.25 * g[q, 0]
            gy = 0.25 * g[q, 1]
            gz = 0.25 * g[q, 2]
            for p in range(4):
                k = uint64(slot[t, p, q])
                G[k, 0] += gx
                G[k, 1] += gy
                G[k, 2] += gz
    n = indptr.shape[0] - 1
    for i in range(n):
        s = 0.0
        for k in range(uint64(indptr[i]), uint64(indptr[i + 1])):
            a = uint64(cols[k])
            if not fixed[a]:
                s += (G[k, 0] * G[k, 0] + G[k, 1] * G[k, 1] + G[k, 2] * G[k, 2]) * inv_mass[a]
        gi[i] = c[i] * s
    out = np.zeros(n)
    for i in range(n):
        for k in range(uint64(indptr[i]), uint64(indptr[i + 1])):
            out[uint64(cols[k])] += gi[i]
    best = 0.0
    for a in range(n):
        if not fixed[a] and out[a] > best:
            best = out[a]
    return best


@njit(cache=True, fastmath=True, nogil=True)
def symplectic_substeps(n_sub, h, pos, vel, inv_mass, b0, fext, gravity, fixed, si, sj, L0, K1, K2,
                        kMg_first, decay_first, kMg, decay, s_state, dl_state, f_buf, f_total, work,
                        no_tets, no_V0, no_kv, tets, V0, kv, vbuf):
    """``n_sub`` symplectic steps of ``h`` s under the same external forces ``fext`` (N): springs and
    Maxwell branches (:func:`surgsim_envs.tissue.msd_kernels.symplectic_step_work`; the first step's
    branch coefficients span the interval since the last commit) plus the nodal volume term
    (:func:`add_forces`), in one compiled call (integrator "subcycled" and plain "symplectic")."""
    for k in range(n_sub):
        for i in range(fext.shape[0]):      # f_total = fext as a loop: a slice assignment costs seconds of compile
            for d in range(3):
                f_total[i, d] = fext[i, d]
        add_forces(pos, tets, V0, kv, vbuf, f_total)
        if k == 0:
            symplectic_step_work(pos, vel, inv_mass, b0, f_total, gravity, fixed, h, si, sj, L0, K1, K2,
                                 kMg_first, decay_first, s_state, dl_state, f_buf, no_tets, no_V0, no_kv, work)
        else:
            symplectic_step_work(pos, vel, inv_mass, b0, f_total, gravity, fixed, h, si, sj, L0, K1, K2,
                                 kMg, decay, s_state, dl_state, f_buf, no_tets, no_V0, no_kv, work)


@njit(cache=True, fastmath=True)
def energy(pos, tets, V0, kv, vbuf):
    """Energy (J) of the nodal-volume term at ``pos``."""
    node_volumes(pos, tets, vbuf)
    total = 0.0
    for i in range(vbuf.shape[0]):
        d = vbuf[i] - V0[i]
        total += 0.5 * kv[i] * d * d / V0[i]
    return total


@njit(cache=True, fastmath=True)
def tangents(pos, tets, vgrad):
    """dV_t/dx_a (m^2) of every tet at ``pos`` into ``vgrad`` (T,4,3)."""
    g = np.empty((4, 3))
    for t in range(tets.shape[0]):
        _tet_volume_gradient(pos, tets, t, g)
        for a in range(4):
            for k in range(3):
                vgrad[t, a, k] = g[a, k]


@njit(cache=True, fastmath=True)
def matvec_add(x, h2, tets, vgrad, c, sbuf, out):
    """out += h2 * sum_i c_i G_i (G_i . x) (the term's Gauss-Newton tangent times x)."""
    sbuf[:] = 0.0
    for t in range(tets.shape[0]):
        q = 0.0
        for a in range(4):
            n = tets[t, a]
            q += vgrad[t, a, 0] * x[n, 0] + vgrad[t, a, 1] * x[n, 1] + vgrad[t, a, 2] * x[n, 2]
        q *= 0.25
        for a in range(4):
            sbuf[tets[t, a]] += q
    for t in range(tets.shape[0]):
        p = 0.0
        for a in range(4):
            n = tets[t, a]
            p += c[n] * sbuf[n]
        p *= 0.25 * h2
        for a in range(4):
            n = tets[t, a]
            out[n, 0] += p * vgrad[t, a, 0]
            out[n, 1] += p * vgrad[t, a, 1]
            out[n, 2] += p * vgrad[t, a, 2]


@njit(cache=True, fastmath=True)
def _matvec(x, diag_m, h2, si, sj, coef_a, coef_g, unit, fixed, out, no_tets, no_grad, no_coef,
            tets, vgrad, c, sbuf):
    _system_matvec(x, diag_m, h2, si, sj, coef_a, coef_g, unit, fixed, out, no_tets, no_grad, no_coef)
    matvec_add(x, h2, tets, vgrad, c, sbuf, out)
    for a in range(x.shape[0]):
        if fixed[a]:
            out[a, 0] = 0.0
            out[a, 1] = 0.0
            out[a, 2] = 0.0


@njit(cache=True, fastmath=True, nogil=True)
def implicit_step(pos, vel, mass, b0, fext, gravity, fixed, kc, dt,
                  si, sj, L0, K1, K2, kMg, decay, kMg_next, s_state, dl_state,
                  f_buf, coef_a, coef_g, unit, diag_m, precond, r, z, p, ap, tol, max_iter,
                  tets, V0, kv, vgrad, c, vbuf, sbuf):
    """One linearly implicit backward-Euler step in place (one Newton step, Jacobi-preconditioned
    matrix-free CG): (M + dt B + dt^2 (K_springs + K_volume + Kc)) v_new = M v + dt (f + f_ext + M g),
    x += dt v_new. As :func:`surgsim_envs.tissue.msd_kernels.implicit_step` with the nodal-volume
    term (``tets``, ``V0``, ``kv`` per node; buffers ``vgrad`` (T,4,3), ``c``, ``vbuf``, ``sbuf`` (N,)).
    Returns the number of CG iterations."""
    n = pos.shape[0]
    no_tets = np.zeros((0, 4), dtype=tets.dtype)
    no_grad = np.zeros((0, 4, 3))
    no_coef = np.zeros(0)
    # np.bool_ / np.int64, not a literal constant: a literal compiles the callee a second time (numba
    # specialises on literal arguments), seconds to tens of seconds of first-use compile for nothing
    spring_forces(pos, si, sj, L0, K1, K2, kMg, decay, s_state, dl_state, np.bool_(True), f_buf)
    spring_tangents(pos, si, sj, L0, K1, K2, kMg_next, s_state, np.bool_(True), coef_a, coef_g, unit)
    add_forces(pos, tets, V0, kv, vbuf, f_buf)
    tangents(pos, tets, vgrad)
    for i in range(n):
        c[i] = kv[i] / V0[i]
    h2 = dt * dt
    for a in range(n):
        diag_m[a] = mass[a] + dt * b0[a] + h2 * kc[a]
        precond[a, 0] = diag_m[a]
        precond[a, 1] = diag_m[a]
        precond[a, 2] = diag_m[a]
    for e in range(si.shape[0]):
        i = si[e]
        j = sj[e]
        for k in range(3):
            d = h2 * (coef_a[e] * unit[e, k] * unit[e, k] + coef_g[e])
            precond[i, k] += d
            precond[j, k] += d
    for t in range(tets.shape[0]):     # diagonal of the volume tangent, cross-tet terms left out
        w = 0.0
        for a in range(4):
            w += c[tets[t, a]]
        w *= h2 / 16.0
        for a in range(4):
            m = tets[t, a]
            for k in range(3):
                precond[m, k] += w * vgrad[t, a, k] * vgrad[t, a, k]
    rhs_norm2 = 0.0
    for a in range(n):
        for k in range(3):
            if fixed[a]:
                z[a, k] = 0.0
                vel[a, k] = 0.0
            else:
                z[a, k] = mass[a] * vel[a, k] + dt * (f_buf[a, k] + fext[a, k] + mass[a] * gravity[k])
                rhs_norm2 += z[a, k] * z[a, k]
    _matvec(vel, diag_m, h2, si, sj, coef_a, coef_g, unit, fixed, ap, no_tets, no_grad, no_coef, tets, vgrad, c, sbuf)
    rz = 0.0
    r_norm2 = 0.0
    for a in range(n):
        for k in range(3):
            rv = z[a, k] - ap[a, k]
            r[a, k] = rv
            zv = rv / precond[a, k]
            z[a, k] = zv
            p[a, k] = zv
            rz += rv * zv
            r_norm2 += rv * rv
    limit = tol * tol * rhs_norm2
    it = 0
    while it < max_iter and r_norm2 > limit and r_norm2 > 1e-300:
        _matvec(p, diag_m, h2, si, sj, coef_a, coef_g, unit, fixed, ap, no_tets, no_grad, no_coef, tets, vgrad, c, sbuf)
        pap = 0.0
        for a in range(n):
            pap += p[a, 0] * ap[a, 0] + p[a, 1] * ap[a, 1] + p[a, 2] * ap[a, 2]
        if not (pap > 0.0):
            break
        alpha = rz / pap
        rz_new = 0.0
        r_norm2 = 0.0
        for a in range(n):
            for k in range(3):
                vel[a, k] += alpha * p[a, k]
                rv = r[a, k] - alpha * ap[a, k]
                r[a, k] = rv
                zv = rv / precond[a, k]
                z[a, k] = zv
                rz_new += rv * zv
                r_norm2 += rv * rv
        beta = rz_new / rz
        rz = rz_new
        for a in range(n):
            for k in range(3):
                p[a, k] = z[a, k] + beta * p[a, k]
        it += 1
    for a in range(n):
        if fixed[a]:
            continue
        pos[a, 0] += dt * vel[a, 0]
        pos[a, 1] += dt * vel[a, 1]
        pos[a, 2] += dt * vel[a, 2]
    return it
