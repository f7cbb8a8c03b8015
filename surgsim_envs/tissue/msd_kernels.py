"""Numba kernels of the nonlinear viscoelastic mass-spring-damper model (the grasping simulation paper).

Every spring ``e`` joins nodes ``si[e]`` -> ``sj[e]`` with rest length ``L0[e]`` (m). Its axial
force (N, positive in tension) is

    f_e = K1[e] * dl + K2[e] * dl**3 + s[e]          dl = |x_j - x_i| - L0[e]  (m)

where ``s`` is the force of the spring's Maxwell branch (spring ``kM`` in series with dashpot
``b1``, relaxation time ``tau = b1 / kM``). The branch is integrated exactly for a strain that
varies linearly over the interval ``h`` since it was last committed (one-term Prony recursion):

    s_new = decay * s_old + kMg * (dl_new - dl_old),   decay = exp(-h/tau),
    kMg = kM * (1 - decay) / (h / tau)   (-> kM as h -> 0)

so it is unconditionally stable.

Optional volume term (Teschner et al. 2004): every tet ``t`` (node indices ``tets[t]``, rest volume
``V0[t]`` m^3, stiffness ``kv[t]`` Pa) stores ``E_t = 0.5 kv (V - V0)^2 / V0``, V the signed volume.
Kernels take ``tets`` of shape (0, 4) when the term is off (the loops then do nothing).

All arrays are float64 (SI) except index arrays (int32/int64)
and masks (bool). The kernels do not allocate: callers pass work buffers.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, uint64


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


@njit(cache=True, fastmath=True, inline="always")
def _tet_volume_gradient(pos, tets, t, g):
    """Signed volume (m^3) of tet t and its gradient dV/dx_a (m^2) into g (4,3)."""
    a = tets[t, 0]
    b = tets[t, 1]
    c = tets[t, 2]
    d = tets[t, 3]
    e10 = pos[b, 0] - pos[a, 0]
    e11 = pos[b, 1] - pos[a, 1]
    e12 = pos[b, 2] - pos[a, 2]
    e20 = pos[c, 0] - pos[a, 0]
    e21 = pos[c, 1] - pos[a, 1]
    e22 = pos[c, 2] - pos[a, 2]
    e30 = pos[d, 0] - pos[a, 0]
    e31 = pos[d, 1] - pos[a, 1]
    e32 = pos[d, 2] - pos[a, 2]
    # (e2 x e3)/6, (e3 x e1)/6, (e1 x e2)/6
    g[1, 0] = (e21 * e32 - e22 * e31) / 6.0
    g[1, 1] = (e22 * e30 - e20 * e32) / 6.0
    g[1, 2] = (e20 * e31 - e21 * e30) / 6.0
    g[2, 0] = (e31 * e12 - e32 * e11) / 6.0
    g[2, 1] = (e32 * e10 - e30 * e12) / 6.0
    g[2, 2] = (e30 * e11 - e31 * e10) / 6.0
    g[3, 0] = (e11 * e22 - e12 * e21) / 6.0
    g[3, 1] = (e12 * e20 - e10 * e22) / 6.0
    g[3, 2] = (e10 * e21 - e11 * e20) / 6.0
    for k in range(3):
        g[0, k] = -(g[1, k] + g[2, k] + g[3, k])
    return e10 * g[1, 0] + e11 * g[1, 1] + e12 * g[1, 2]


@njit(cache=True, fastmath=True)
def volume_forces(pos, tets, V0, kv, f_out):
    """Add the volume-term nodal forces ``-kv (V - V0)/V0 dV/dx`` (N) to ``f_out`` (N,3)."""
    for t in range(tets.shape[0]):
        a = tets[t, 0]
        b = tets[t, 1]
        c = tets[t, 2]
        d = tets[t, 3]
        e10 = pos[b, 0] - pos[a, 0]
        e11 = pos[b, 1] - pos[a, 1]
        e12 = pos[b, 2] - pos[a, 2]
        e20 = pos[c, 0] - pos[a, 0]
        e21 = pos[c, 1] - pos[a, 1]
        e22 = pos[c, 2] - pos[a, 2]
        e30 = pos[d, 0] - pos[a, 0]
        e31 = pos[d, 1] - pos[a, 1]
        e32 = pos[d, 2] - pos[a, 2]
        g10 = e21 * e32 - e22 * e31      # 6 dV/dx_b = e2 x e3
        g11 = e22 * e30 - e20 * e32
        g12 = e20 * e31 - e21 * e30
        g20 = e31 * e12 - e32 * e11      # 6 dV/dx_c = e3 x e1
        g21 = e32 * e10 - e30 * e12
        g22 = e30 * e11 - e31 * e10
        g30 = e11 * e22 - e12 * e21      # 6 dV/dx_d = e1 x e2
        g31 = e12 * e20 - e10 * e22
        g32 = e10 * e21 - e11 * e20
        vol = (e10 * g10 + e11 * g11 + e12 * g12) / 6.0
        k = -kv[t] * (vol - V0[t]) / (6.0 * V0[t])
        f_out[b, 0] += k * g10
        f_out[b, 1] += k * g11
        f_out[b, 2] += k * g12
        f_out[c, 0] += k * g20
        f_out[c, 1] += k * g21
        f_out[c, 2] += k * g22
        f_out[d, 0] += k * g30
        f_out[d, 1] += k * g31
        f_out[d, 2] += k * g32
        f_out[a, 0] -= k * (g10 + g20 + g30)
        f_out[a, 1] -= k * (g11 + g21 + g31)
        f_out[a, 2] -= k * (g12 + g22 + g32)


@njit(cache=True, inline="always")
def _tet_volume(pos, tets, t):
    """Signed volume (m^3) of tet t: the value of :func:`_tet_volume_gradient` by the same operations in
    the same order (e1 . (e2 x e3)/6), without the three gradients it does not need."""
    a = tets[t, 0]
    b = tets[t, 1]
    c = tets[t, 2]
    d = tets[t, 3]
    e10 = pos[b, 0] - pos[a, 0]
    e11 = pos[b, 1] - pos[a, 1]
    e12 = pos[b, 2] - pos[a, 2]
    e20 = pos[c, 0] - pos[a, 0]
    e21 = pos[c, 1] - pos[a, 1]
    e22 = pos[c, 2] - pos[a, 2]
    e30 = pos[d, 0] - pos[a, 0]
    e31 = pos[d, 1] - pos[a, 1]
    e32 = pos[d, 2] - pos[a, 2]
    return (e10 * ((e21 * e32 - e22 * e31) / 6.0) + e11 * ((e22 * e30 - e20 * e32) / 6.0)
            + e12 * ((e20 * e31 - e21 * e30) / 6.0))


@njit(cache=True)
def tet_volumes(pos, tets, out):
    """Signed tet volumes (m^3) into ``out`` (T,), by the arithmetic of :func:`volume_energy` (strict IEEE:
    rest volumes taken with it make the rest state's volume energy exactly 0 in every caller)."""
    for t in range(tets.shape[0]):
        out[t] = _tet_volume(pos, tets, t)


@njit(cache=True)
def volume_energy(pos, tets, V0, kv):
    """Volume-term energy (J): sum over tets of 0.5 kv (V - V0)^2 / V0 (strict IEEE, no fastmath: the
    same sum wherever it is compiled, e.g. the guard's energy reference in the scene's compiled loop,
    which takes it every ``check_every`` steps: the volumes alone, no gradients)."""
    energy = 0.0
    for t in range(tets.shape[0]):
        dv = _tet_volume(pos, tets, t) - V0[t]
        energy += 0.5 * kv[t] * dv * dv / V0[t]
    return energy


@njit(cache=True, fastmath=True)
def volume_tangents(pos, tets, V0, kv, vgrad, vcoef):
    """Gauss-Newton tangent of the volume term per tet: ``K_t = vcoef g g^T`` (N/m) with
    g = dV/dx (m^2, into ``vgrad`` (T,4,3)) and vcoef = kv / V0 (Pa/m^3); the indefinite
    second-derivative part ``kv (V - V0)/V0 d2V/dx2`` is left out (small near rest)."""
    g = np.empty((4, 3))
    for t in range(tets.shape[0]):
        _tet_volume_gradient(pos, tets, t, g)
        for q in range(4):
            for k in range(3):
                vgrad[t, q, k] = g[q, k]
        vcoef[t] = kv[t] / V0[t]


@njit(cache=True, fastmath=True)
def _volume_matvec(x, h2, tets, vgrad, vcoef, out):
    """out += h2 * sum_t vcoef_t g_t (g_t . x) (the volume term's Gauss-Newton tangent times x)."""
    for t in range(tets.shape[0]):
        q = 0.0
        for a in range(4):
            n = tets[t, a]
            q += vgrad[t, a, 0] * x[n, 0] + vgrad[t, a, 1] * x[n, 1] + vgrad[t, a, 2] * x[n, 2]
        c = h2 * vcoef[t] * q
        for a in range(4):
            n = tets[t, a]
            out[n, 0] += c * vgrad[t, a, 0]
            out[n, 1] += c * vgrad[t, a, 1]
            out[n, 2] += c * vgrad[t, a, 2]


@njit(cache=True, fastmath=True, error_model="numpy", nogil=True)
def spring_forces_passes(pos, si, sj, L0, K1, K2, kMg, decay, s_state, dl_state, commit, f_out, work):
    """:func:`spring_forces` (same forces, same branch update) in three passes over a (4, E) work
    buffer ``work`` (any content; overwritten): (1) gather the spring vectors x_j - x_i into
    structure-of-arrays rows; (2) per spring the force over length, f / l, a loop over contiguous
    arrays with no scatter and no Python error checks (``error_model="numpy"``), which the compiler
    vectorises (sqrt, division); (3) scatter +-(f/l) d onto the nodes in spring order, keeping node
    ``si[e]``'s running sum in registers while consecutive springs share it (loaded from and stored to
    ``f_out`` around each run, so every node receives the same additions in the same order as in
    :func:`spring_forces`; the lattices sort springs by ``si``, so no store-to-load chain runs through
    memory; any order gives the same sums). A spring of length <= 1e-300 m exerts no force (as in
    :func:`spring_forces`). Measured here: bit for bit the forces of :func:`spring_forces` called on
    its own, and the tasks' trajectories identical to the single-pass kernel's (fastmath lets the
    compiler contract arithmetic differently in other contexts: tests hold the two to 1e-12
    relative); ~1.8x faster on the tasks' lattices (CHANGELOG.md "Env step: three-pass spring kernel, env fast paths, Grasp sub-cycling"). Node
    indices are read as unsigned (the springs' nodes are valid, non-negative ids): numba then emits
    no negative-index wrap-around per access, 5-17 % of the call on the tasks' lattices with the same
    forces bit for bit (CHANGELOG.md "Env step: unsigned spring indices, lazy contact zeroing")."""
    ne = si.shape[0]
    wx = work[0]
    wy = work[1]
    wz = work[2]
    wc = work[3]
    for e in range(ne):
        i = uint64(si[e])
        j = uint64(sj[e])
        wx[e] = pos[j, 0] - pos[i, 0]
        wy[e] = pos[j, 1] - pos[i, 1]
        wz[e] = pos[j, 2] - pos[i, 2]
    # pass 2, written out twice on purpose: ``commit`` is tested outside the loops so each loop
    # body stays branch-free for the vectoriser (the only difference: committing the branch state)
    if commit:
        for e in range(ne):
            dx = wx[e]
            dy = wy[e]
            dz = wz[e]
            length = math.sqrt(dx * dx + dy * dy + dz * dz)
            dl = length - L0[e]
            sb = decay[e] * s_state[e] + kMg[e] * (dl - dl_state[e])
            s_state[e] = sb
            dl_state[e] = dl
            f = K1[e] * dl + K2[e] * dl * dl * dl + sb
            wc[e] = f / length if length > 1e-300 else 0.0
    else:
        for e in range(ne):
            dx = wx[e]
            dy = wy[e]
            dz = wz[e]
            length = math.sqrt(dx * dx + dy * dy + dz * dz)
            dl = length - L0[e]
            sb = decay[e] * s_state[e] + kMg[e] * (dl - dl_state[e])
            f = K1[e] * dl + K2[e] * dl * dl * dl + sb
            wc[e] = f / length if length > 1e-300 else 0.0
    for a in range(pos.shape[0]):
        f_out[a, 0] = 0.0
        f_out[a, 1] = 0.0
        f_out[a, 2] = 0.0
    if ne == 0:
        return
    cur = uint64(si[0])
    ax = f_out[cur, 0]
    ay = f_out[cur, 1]
    az = f_out[cur, 2]
    for e in range(ne):
        i = uint64(si[e])
        if i != cur:
            f_out[cur, 0] = ax
            f_out[cur, 1] = ay
            f_out[cur, 2] = az
            cur = i
            ax = f_out[cur, 0]        # what earlier springs (as their j side) added to it
            ay = f_out[cur, 1]
            az = f_out[cur, 2]
        j = uint64(sj[e])
        c = wc[e]
        fx = c * wx[e]
        fy = c * wy[e]
        fz = c * wz[e]
        ax += fx
        ay += fy
        az += fz
        f_out[j, 0] -= fx
        f_out[j, 1] -= fy
        f_out[j, 2] -= fz
    f_out[cur, 0] = ax
    f_out[cur, 1] = ay
    f_out[cur, 2] = az


@njit(cache=True, fastmath=True, nogil=True)
def symplectic_step(pos, vel, inv_mass, b0, fext, gravity, fixed, dt,
                    si, sj, L0, K1, K2, kMg, decay, s_state, dl_state, f_buf, tets, V0, kv):
    """One semi-implicit (symplectic) Euler step in place:

    v += dt * ((f_spring + f_volume + f_ext - b0 v) / m + g);  x += dt * v   (fixed nodes untouched).

    Allocates the (4, E) work buffer of :func:`symplectic_step_work` (the hot callers pass their own).
    """
    symplectic_step_work(pos, vel, inv_mass, b0, fext, gravity, fixed, dt, si, sj, L0, K1, K2, kMg, decay,
                         s_state, dl_state, f_buf, tets, V0, kv, np.empty((4, si.shape[0])))


@njit(cache=True, fastmath=True, nogil=True)
def symplectic_step_work(pos, vel, inv_mass, b0, fext, gravity, fixed, dt,
                         si, sj, L0, K1, K2, kMg, decay, s_state, dl_state, f_buf, tets, V0, kv, work):
    """:func:`symplectic_step` with the spring pass's (4, E) float64 work buffer ``work`` given
    (:func:`spring_forces_passes`)."""
    # np.bool_ / np.int64, not a literal constant: a literal compiles the callee a second time (numba
    # specialises on literal arguments), seconds to tens of seconds of first-use compile for nothing
    spring_forces_passes(pos, si, sj, L0, K1, K2, kMg, decay, s_state, dl_state, np.bool_(True), f_buf, work)
    volume_forces(pos, tets, V0, kv, f_buf)
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
def _system_matvec(x, diag_m, h2, si, sj, coef_a, coef_g, unit, fixed, out, tets, vgrad, vcoef):
    """out = (diag_m + h2 * K) x with fixed rows/cols removed (K: springs + volume term)."""
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
    _volume_matvec(x, h2, tets, vgrad, vcoef, out)
    for a in range(n):
        if fixed[a]:
            out[a, 0] = 0.0
            out[a, 1] = 0.0
            out[a, 2] = 0.0


@njit(cache=True, fastmath=True, nogil=True)
def implicit_step(pos, vel, mass, b0, fext, gravity, fixed, kc, dt,
                  si, sj, L0, K1, K2, kMg, decay, kMg_next, s_state, dl_state,
                  f_buf, coef_a, coef_g, unit, diag_m, precond, r, z, p, ap, tol, max_iter,
                  tets, V0, kv, vgrad, vcoef):
    """One linearly implicit backward-Euler step (one Newton step) in place.

    Solves (M + dt B + dt^2 (K + Kc)) v_new = M v + dt (f(x) + f_ext + M g) by Jacobi-
    preconditioned conjugate gradients (matrix-free), then x += dt * v_new. K is the spring
    tangent (Maxwell branch included through kMg), B = diag(b0), Kc = diag(kc) the external
    contact stiffness; the volume term (``tets``, ``V0``, ``kv``) adds its forces and its
    Gauss-Newton tangent (``vgrad``/``vcoef`` buffers). ``kMg``/``decay`` bring the Maxwell branches from their last commit up to
    ``pos``; ``kMg_next`` is the branches' stiffness over this step of length ``dt``.
    Returns the number of CG iterations.
    """
    n = pos.shape[0]
    # branch state is committed at x_n; tangents at x_n with the branch's stiffness over the coming step
    # np.bool_ / np.int64, not a literal constant: a literal compiles the callee a second time (numba
    # specialises on literal arguments), seconds to tens of seconds of first-use compile for nothing
    spring_forces(pos, si, sj, L0, K1, K2, kMg, decay, s_state, dl_state, np.bool_(True), f_buf)
    spring_tangents(pos, si, sj, L0, K1, K2, kMg_next, s_state, np.bool_(True), coef_a, coef_g, unit)
    volume_forces(pos, tets, V0, kv, f_buf)
    volume_tangents(pos, tets, V0, kv, vgrad, vcoef)
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
    for t in range(tets.shape[0]):
        for q in range(4):
            a = tets[t, q]
            for c in range(3):
                precond[a, c] += h2 * vcoef[t] * vgrad[t, q, c] * vgrad[t, q, c]
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
    _system_matvec(vel, diag_m, h2, si, sj, coef_a, coef_g, unit, fixed, ap, tets, vgrad, vcoef)
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
        _system_matvec(p, diag_m, h2, si, sj, coef_a, coef_g, unit, fixed, ap, tets, vgrad, vcoef)
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
def gershgorin_lambda_max(pos, inv_mass, si, sj, L0, K1, K2, kM, s_state, dl_state, decay, kMg, tets, V0, kv):
    """Upper bound (1/s^2) of the largest eigenvalue of M^-1 K_tangent (row-sum norm).

    Uses the instantaneous Maxwell stiffness kM (the stiffest the branch can be), the
    tension part of the geometric stiffness and the volume term's Gauss-Newton tangent
    ``kv/V0 g g^T`` (row sum ``kv/V0 |g_ac| sum_bd |g_bd|``).
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
    g4 = np.empty((4, 3))
    for t in range(tets.shape[0]):
        _tet_volume_gradient(pos, tets, t, g4)
        total = 0.0
        for q in range(4):
            total += abs(g4[q, 0]) + abs(g4[q, 1]) + abs(g4[q, 2])
        c = kv[t] / V0[t] * total
        for q in range(4):
            a = tets[t, q]
            rows[a, 0] += c * abs(g4[q, 0])
            rows[a, 1] += c * abs(g4[q, 1])
            rows[a, 2] += c * abs(g4[q, 2])
    best = 0.0
    for a in range(n):
        for c in range(3):
            v = rows[a, c] * inv_mass[a]
            if v > best:
                best = v
    return best
