"""Numba kernels of the corotational linear tetrahedral FEM (hot loops only; see fem.py).

Per element e with rest edge-matrix inverse ``dm_inv`` (F = Ds Dm^-1) and rotation R_e the
stiffness product is ``P(y) = R K_e (R^T y - X)`` (``subtract_rest``) or ``R K_e R^T y``; it is
evaluated in tensor form: ``G = R^T (Ys Dm^-1)`` (minus I), ``eps = sym(G)``,
``sigma = 2 mu dev(eps) + p I`` with ``p = kappa tr(eps)`` (standard) or the averaged nodal
pressure (ANP), and nodal vectors ``V R sigma grad N_a``.  Elastic force = -P(x).
Units: m, N, Pa, s.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always", error_model="numpy")
def _element_rotation(x, tets, dm_inv, quats, rots, e, max_iter, tol, eps, want_strain):
    """Polar rotation of tet e (see :func:`update_rotations`); updates quats[e] and rots[e].
    With ``want_strain`` also writes the corotated strain sym(R^T F) - I into eps[6]."""
    a, b, c, d = tets[e, 0], tets[e, 1], tets[e, 2], tets[e, 3]
    m00, m01, m02 = dm_inv[e, 0, 0], dm_inv[e, 0, 1], dm_inv[e, 0, 2]
    m10, m11, m12 = dm_inv[e, 1, 0], dm_inv[e, 1, 1], dm_inv[e, 1, 2]
    m20, m21, m22 = dm_inv[e, 2, 0], dm_inv[e, 2, 1], dm_inv[e, 2, 2]
    d1, d2, d3 = x[b, 0] - x[a, 0], x[c, 0] - x[a, 0], x[d, 0] - x[a, 0]
    f00 = d1 * m00 + d2 * m10 + d3 * m20
    f01 = d1 * m01 + d2 * m11 + d3 * m21
    f02 = d1 * m02 + d2 * m12 + d3 * m22
    d1, d2, d3 = x[b, 1] - x[a, 1], x[c, 1] - x[a, 1], x[d, 1] - x[a, 1]
    f10 = d1 * m00 + d2 * m10 + d3 * m20
    f11 = d1 * m01 + d2 * m11 + d3 * m21
    f12 = d1 * m02 + d2 * m12 + d3 * m22
    d1, d2, d3 = x[b, 2] - x[a, 2], x[c, 2] - x[a, 2], x[d, 2] - x[a, 2]
    f20 = d1 * m00 + d2 * m10 + d3 * m20
    f21 = d1 * m01 + d2 * m11 + d3 * m21
    f22 = d1 * m02 + d2 * m12 + d3 * m22
    qw, qx, qy, qz = quats[e, 0], quats[e, 1], quats[e, 2], quats[e, 3]
    for it in range(max_iter):
        r00 = 1.0 - 2.0 * (qy * qy + qz * qz)
        r01 = 2.0 * (qx * qy - qw * qz)
        r02 = 2.0 * (qx * qz + qw * qy)
        r10 = 2.0 * (qx * qy + qw * qz)
        r11 = 1.0 - 2.0 * (qx * qx + qz * qz)
        r12 = 2.0 * (qy * qz - qw * qx)
        r20 = 2.0 * (qx * qz - qw * qy)
        r21 = 2.0 * (qy * qz + qw * qx)
        r22 = 1.0 - 2.0 * (qx * qx + qy * qy)
        # A = R^T F
        a00 = r00 * f00 + r10 * f10 + r20 * f20
        a01 = r00 * f01 + r10 * f11 + r20 * f21
        a02 = r00 * f02 + r10 * f12 + r20 * f22
        a10 = r01 * f00 + r11 * f10 + r21 * f20
        a11 = r01 * f01 + r11 * f11 + r21 * f21
        a12 = r01 * f02 + r11 * f12 + r21 * f22
        a20 = r02 * f00 + r12 * f10 + r22 * f20
        a21 = r02 * f01 + r12 * f11 + r22 * f21
        a22 = r02 * f02 + r12 * f12 + r22 * f22
        b0 = a21 - a12
        b1 = a02 - a20
        b2 = a10 - a01
        tr = a00 + a11 + a22
        n00 = tr - a00
        n11 = tr - a11
        n22 = tr - a22
        n01 = -0.5 * (a01 + a10)
        n12 = -0.5 * (a12 + a21)
        n02 = -0.5 * (a02 + a20)
        c00 = n11 * n22 - n12 * n12
        c01 = n02 * n12 - n01 * n22
        c02 = n01 * n12 - n02 * n11
        det = n00 * c00 + n01 * c01 + n02 * c02
        scale = abs(n00) + abs(n11) + abs(n22) + 1e-30
        if det > 1e-6 * scale * scale * scale:
            c11 = n00 * n22 - n02 * n02
            c12 = n01 * n02 - n00 * n12
            c22 = n00 * n11 - n01 * n01
            inv = 1.0 / det
            w0 = (c00 * b0 + c01 * b1 + c02 * b2) * inv
            w1 = (c01 * b0 + c11 * b1 + c12 * b2) * inv
            w2 = (c02 * b0 + c12 * b1 + c22 * b2) * inv
        else:  # near-singular (inverted/degenerate): damped gradient step
            inv = 1.0 / (abs(tr) + 1e-9)
            w0, w1, w2 = b0 * inv, b1 * inv, b2 * inv
        wn2 = w0 * w0 + w1 * w1 + w2 * w2
        if wn2 < tol * tol:
            break
        if wn2 > 1.0:
            wn = math.sqrt(wn2)
            w0 /= wn
            w1 /= wn
            w2 /= wn
        # q <- q (x) (1, w/2), normalised
        px, py, pz = 0.5 * w0, 0.5 * w1, 0.5 * w2
        nw = qw - qx * px - qy * py - qz * pz
        nx = qx + qw * px + qy * pz - qz * py
        ny = qy + qw * py + qz * px - qx * pz
        nz = qz + qw * pz + qx * py - qy * px
        nrm = 1.0 / math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
        qw, qx, qy, qz = nw * nrm, nx * nrm, ny * nrm, nz * nrm
    quats[e, 0], quats[e, 1], quats[e, 2], quats[e, 3] = qw, qx, qy, qz
    r00 = 1.0 - 2.0 * (qy * qy + qz * qz)
    r01 = 2.0 * (qx * qy - qw * qz)
    r02 = 2.0 * (qx * qz + qw * qy)
    r10 = 2.0 * (qx * qy + qw * qz)
    r11 = 1.0 - 2.0 * (qx * qx + qz * qz)
    r12 = 2.0 * (qy * qz - qw * qx)
    r20 = 2.0 * (qx * qz - qw * qy)
    r21 = 2.0 * (qy * qz + qw * qx)
    r22 = 1.0 - 2.0 * (qx * qx + qy * qy)
    rots[e, 0, 0], rots[e, 0, 1], rots[e, 0, 2] = r00, r01, r02
    rots[e, 1, 0], rots[e, 1, 1], rots[e, 1, 2] = r10, r11, r12
    rots[e, 2, 0], rots[e, 2, 1], rots[e, 2, 2] = r20, r21, r22
    if want_strain:
        eps[0] = r00 * f00 + r10 * f10 + r20 * f20 - 1.0
        eps[1] = r01 * f01 + r11 * f11 + r21 * f21 - 1.0
        eps[2] = r02 * f02 + r12 * f12 + r22 * f22 - 1.0
        eps[3] = 0.5 * (r00 * f01 + r10 * f11 + r20 * f21 + r01 * f00 + r11 * f10 + r21 * f20)
        eps[4] = 0.5 * (r01 * f02 + r11 * f12 + r21 * f22 + r02 * f01 + r12 * f11 + r22 * f21)
        eps[5] = 0.5 * (r02 * f00 + r12 * f10 + r22 * f20 + r00 * f02 + r10 * f12 + r20 * f22)


@njit(cache=True, error_model="numpy")
def update_rotations(x, tets, dm_inv, quats, rots, max_iter, tol):
    """Rotation R of each tet's deformation gradient F = R S (polar decomposition).

    Newton iteration on the rotation, warm-started from ``quats`` (T, 4) (w, x, y, z), which are
    updated; ``rots`` (T, 3, 3) receives R. With A = R^T F, S = sym(A), one step solves
    ``(tr(S) I - S) w = axial(A - A^T)`` and sets R <- R exp(w^) (quadratic convergence; the
    fixed-rate variant of Mueller et al. 2016 converges only by ~1/3 per iteration near S = I).
    Stops per element when |w| < ``tol`` rad or after ``max_iter`` iterations; with a warm start
    one iteration per time step suffices. Steps are clamped to 1 rad (inverted elements).
    """
    eps = np.empty(6)
    for e in range(tets.shape[0]):
        _element_rotation(x, tets, dm_inv, quats, rots, e, max_iter, tol, eps, False)


@njit(cache=True, inline="always", error_model="numpy")
def _element_strain(y, tets, dm_inv, rots, e, subtract_rest, eps):
    """eps (6,) = sym(R^T Ys Dm^-1) [- I], stored as xx, yy, zz, xy, yz, zx (tensor, not engineering)."""
    a, b, c, d = tets[e, 0], tets[e, 1], tets[e, 2], tets[e, 3]
    m00, m01, m02 = dm_inv[e, 0, 0], dm_inv[e, 0, 1], dm_inv[e, 0, 2]
    m10, m11, m12 = dm_inv[e, 1, 0], dm_inv[e, 1, 1], dm_inv[e, 1, 2]
    m20, m21, m22 = dm_inv[e, 2, 0], dm_inv[e, 2, 1], dm_inv[e, 2, 2]
    # g = Ys Dm^-1, row by row
    d1, d2, d3 = y[b, 0] - y[a, 0], y[c, 0] - y[a, 0], y[d, 0] - y[a, 0]
    g00 = d1 * m00 + d2 * m10 + d3 * m20
    g01 = d1 * m01 + d2 * m11 + d3 * m21
    g02 = d1 * m02 + d2 * m12 + d3 * m22
    d1, d2, d3 = y[b, 1] - y[a, 1], y[c, 1] - y[a, 1], y[d, 1] - y[a, 1]
    g10 = d1 * m00 + d2 * m10 + d3 * m20
    g11 = d1 * m01 + d2 * m11 + d3 * m21
    g12 = d1 * m02 + d2 * m12 + d3 * m22
    d1, d2, d3 = y[b, 2] - y[a, 2], y[c, 2] - y[a, 2], y[d, 2] - y[a, 2]
    g20 = d1 * m00 + d2 * m10 + d3 * m20
    g21 = d1 * m01 + d2 * m11 + d3 * m21
    g22 = d1 * m02 + d2 * m12 + d3 * m22
    r00, r01, r02 = rots[e, 0, 0], rots[e, 0, 1], rots[e, 0, 2]
    r10, r11, r12 = rots[e, 1, 0], rots[e, 1, 1], rots[e, 1, 2]
    r20, r21, r22 = rots[e, 2, 0], rots[e, 2, 1], rots[e, 2, 2]
    # h = R^T g
    h00 = r00 * g00 + r10 * g10 + r20 * g20
    h11 = r01 * g01 + r11 * g11 + r21 * g21
    h22 = r02 * g02 + r12 * g12 + r22 * g22
    h01 = r00 * g01 + r10 * g11 + r20 * g21
    h10 = r01 * g00 + r11 * g10 + r21 * g20
    h12 = r01 * g02 + r11 * g12 + r21 * g22
    h21 = r02 * g01 + r12 * g11 + r22 * g21
    h20 = r02 * g00 + r12 * g10 + r22 * g20
    h02 = r00 * g02 + r10 * g12 + r20 * g22
    off = 1.0 if subtract_rest else 0.0
    eps[0] = h00 - off
    eps[1] = h11 - off
    eps[2] = h22 - off
    eps[3] = 0.5 * (h01 + h10)
    eps[4] = 0.5 * (h12 + h21)
    eps[5] = 0.5 * (h20 + h02)


@njit(cache=True, inline="always", error_model="numpy")
def _scatter_stress(tets, dm_inv, vol, rots, e, s, out):
    """out[node] += V R sigma grad N (sigma symmetric given as s[6])."""
    v = vol[e]
    s0, s1, s2, s3, s4, s5 = s[0], s[1], s[2], s[3], s[4], s[5]
    for i in range(3):  # row i of P = V R sigma
        r0, r1, r2 = rots[e, i, 0], rots[e, i, 1], rots[e, i, 2]
        p0 = v * (r0 * s0 + r1 * s3 + r2 * s5)
        p1 = v * (r0 * s3 + r1 * s1 + r2 * s4)
        p2 = v * (r0 * s5 + r1 * s4 + r2 * s2)
        f1 = p0 * dm_inv[e, 0, 0] + p1 * dm_inv[e, 0, 1] + p2 * dm_inv[e, 0, 2]
        f2 = p0 * dm_inv[e, 1, 0] + p1 * dm_inv[e, 1, 1] + p2 * dm_inv[e, 1, 2]
        f3 = p0 * dm_inv[e, 2, 0] + p1 * dm_inv[e, 2, 1] + p2 * dm_inv[e, 2, 2]
        out[tets[e, 1], i] += f1
        out[tets[e, 2], i] += f2
        out[tets[e, 3], i] += f3
        out[tets[e, 0], i] -= f1 + f2 + f3


@njit(cache=True, error_model="numpy")
def stiffness_product(y, tets, dm_inv, vol, mu, lam, rots, subtract_rest, anp, kappa_node, node_vol,
                      theta_node, eps_buf, out, x_rot, quats, rot_iters, rot_tol, y_is_x_rot):
    """out (N,3) = R K R^T y - [R K X]: the (warped) stiffness applied to y (N/m * m = N).

    With ``subtract_rest`` this is minus the elastic force at positions y. ``anp`` selects the
    averaged-nodal-pressure volumetric term (``kappa_node``, ``node_vol`` per node); otherwise
    each tet uses its own lambda. ``theta_node`` (N,) and ``eps_buf`` (T, 6) are work arrays.
    With ``rot_iters`` > 0 the rotations are first updated from ``x_rot`` (fused, one pass;
    ``y_is_x_rot`` says y and x_rot are the same positions so the strain comes for free).
    """
    update = rot_iters > 0
    fused = update and subtract_rest and y_is_x_rot  # strain comes out of the rotation update
    out[:] = 0.0
    eps = np.empty(6)
    s = np.empty(6)
    nt = tets.shape[0]
    if not anp:
        for e in range(nt):
            if update:
                _element_rotation(x_rot, tets, dm_inv, quats, rots, e, rot_iters, rot_tol, eps, fused)
            if not fused:
                _element_strain(y, tets, dm_inv, rots, e, subtract_rest, eps)
            tr = eps[0] + eps[1] + eps[2]
            m2 = 2.0 * mu[e]
            lt = lam[e] * tr
            s[0] = m2 * eps[0] + lt
            s[1] = m2 * eps[1] + lt
            s[2] = m2 * eps[2] + lt
            s[3] = m2 * eps[3]
            s[4] = m2 * eps[4]
            s[5] = m2 * eps[5]
            _scatter_stress(tets, dm_inv, vol, rots, e, s, out)
        return
    theta_node[:] = 0.0
    for e in range(nt):
        if update:
            _element_rotation(x_rot, tets, dm_inv, quats, rots, e, rot_iters, rot_tol, eps, fused)
        if not fused:
            _element_strain(y, tets, dm_inv, rots, e, subtract_rest, eps)
        for k in range(6):
            eps_buf[e, k] = eps[k]
        q = 0.25 * vol[e] * (eps[0] + eps[1] + eps[2])
        for k in range(4):
            theta_node[tets[e, k]] += q
    for a in range(theta_node.shape[0]):  # nodal pressure p_a = kappa_a theta_a
        theta_node[a] = kappa_node[a] * theta_node[a] / node_vol[a]
    for e in range(nt):
        pbar = 0.25 * (theta_node[tets[e, 0]] + theta_node[tets[e, 1]] + theta_node[tets[e, 2]] + theta_node[tets[e, 3]])
        tr3 = (eps_buf[e, 0] + eps_buf[e, 1] + eps_buf[e, 2]) / 3.0
        m2 = 2.0 * mu[e]
        s[0] = m2 * (eps_buf[e, 0] - tr3) + pbar
        s[1] = m2 * (eps_buf[e, 1] - tr3) + pbar
        s[2] = m2 * (eps_buf[e, 2] - tr3) + pbar
        s[3] = m2 * eps_buf[e, 3]
        s[4] = m2 * eps_buf[e, 4]
        s[5] = m2 * eps_buf[e, 5]
        _scatter_stress(tets, dm_inv, vol, rots, e, s, out)


@njit(cache=True, error_model="numpy")
def elastic_energy(x, tets, dm_inv, vol, mu, lam, rots, anp, kappa_node, node_vol, theta_node):
    """Stored energy (J) of the (corotated) linear material at positions x."""
    eps = np.empty(6)
    energy = 0.0
    theta_node[:] = 0.0
    for e in range(tets.shape[0]):
        _element_strain(x, tets, dm_inv, rots, e, True, eps)
        tr = eps[0] + eps[1] + eps[2]
        ee = eps[0] ** 2 + eps[1] ** 2 + eps[2] ** 2 + 2.0 * (eps[3] ** 2 + eps[4] ** 2 + eps[5] ** 2)
        if anp:
            energy += vol[e] * mu[e] * (ee - tr * tr / 3.0)
            for k in range(4):
                theta_node[tets[e, k]] += 0.25 * vol[e] * tr
        else:
            energy += vol[e] * (mu[e] * ee + 0.5 * lam[e] * tr * tr)
    if anp:
        for a in range(theta_node.shape[0]):
            th = theta_node[a] / node_vol[a]
            energy += 0.5 * kappa_node[a] * node_vol[a] * th * th
    return energy


@njit(cache=True, error_model="numpy")
def count_inverted(x, tets):
    """Number of tets with det F <= 0 (rest tets are positively oriented)."""
    n = 0
    for e in range(tets.shape[0]):
        a, b, c, d = tets[e, 0], tets[e, 1], tets[e, 2], tets[e, 3]
        u0, u1, u2 = x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2]
        v0, v1, v2 = x[c, 0] - x[a, 0], x[c, 1] - x[a, 1], x[c, 2] - x[a, 2]
        w0, w1, w2 = x[d, 0] - x[a, 0], x[d, 1] - x[a, 1], x[d, 2] - x[a, 2]
        det = u0 * (v1 * w2 - v2 * w1) - u1 * (v0 * w2 - v2 * w0) + u2 * (v0 * w1 - v1 * w0)
        if not det > 0.0:
            n += 1
    return n


@njit(cache=True, error_model="numpy")
def symplectic_step(x, v, fext, masses, alpha, gravity, fixed, dt, beta, corotational, rot_iters, rot_tol,
                    tets, dm_inv, vol, mu, lam, quats, rots, anp, kappa_node, node_vol, theta_node, eps_buf,
                    y_buf, f_buf):
    """One semi-implicit (symplectic) Euler step in place.

    v += dt (f_el(x, v) + f_ext + m g) / m, then mass damping v /= (1 + alpha dt), then x += dt v.
    Stiffness (Rayleigh) damping beta K v enters as the stiffness product of x + beta v.
    """
    iters = rot_iters if corotational else 0
    if beta > 0.0:
        for i in range(x.shape[0]):
            for k in range(3):
                y_buf[i, k] = x[i, k] + beta * v[i, k]
        stiffness_product(y_buf, tets, dm_inv, vol, mu, lam, rots, True, anp, kappa_node, node_vol,
                          theta_node, eps_buf, f_buf, x, quats, iters, rot_tol, False)
    else:
        stiffness_product(x, tets, dm_inv, vol, mu, lam, rots, True, anp, kappa_node, node_vol,
                          theta_node, eps_buf, f_buf, x, quats, iters, rot_tol, True)
    for i in range(x.shape[0]):
        if fixed[i]:
            for k in range(3):
                v[i, k] = 0.0
            continue
        inv_m = 1.0 / masses[i]
        damp = 1.0 / (1.0 + alpha[i] * dt)
        for k in range(3):
            v[i, k] = (v[i, k] + dt * ((fext[i, k] - f_buf[i, k]) * inv_m + gravity[k])) * damp
            x[i, k] += dt * v[i, k]


@njit(cache=True, error_model="numpy")
def _apply_system(y, diag, c_k, tets, dm_inv, vol, mu, lam, rots, anp, kappa_node, node_vol, theta_node,
                  eps_buf, free, out):
    """out = (diag + c_k R K R^T) y on free DOFs (zero rows/cols at fixed nodes)."""
    stiffness_product(y, tets, dm_inv, vol, mu, lam, rots, False, anp, kappa_node, node_vol,
                      theta_node, eps_buf, out, y, eps_buf, 0, 0.0, False)
    for i in range(y.shape[0]):
        if free[i]:
            for k in range(3):
                out[i, k] = diag[i] * y[i, k] + c_k * out[i, k]
        else:
            for k in range(3):
                out[i, k] = 0.0


@njit(cache=True, error_model="numpy")
def pcg_solve(rhs, x, diag, c_k, precond, free, tol, max_iter, tets, dm_inv, vol, mu, lam, rots, anp,
              kappa_node, node_vol, theta_node, eps_buf):
    """Jacobi-preconditioned CG for (diag M' + c_k R K R^T) x = rhs on free nodes; x is the initial
    guess (values at fixed nodes are held, i.e. must be zero). Returns the iteration count."""
    n = rhs.shape[0]
    r = np.empty((n, 3))
    z = np.empty((n, 3))
    p = np.empty((n, 3))
    ap = np.empty((n, 3))
    _apply_system(x, diag, c_k, tets, dm_inv, vol, mu, lam, rots, anp, kappa_node, node_vol, theta_node,
                  eps_buf, free, ap)
    rz = 0.0
    bnorm = 0.0
    for i in range(n):
        for k in range(3):
            if free[i]:
                r[i, k] = rhs[i, k] - ap[i, k]
                bnorm += rhs[i, k] * rhs[i, k]
            else:
                r[i, k] = 0.0
            z[i, k] = r[i, k] / precond[i]
            p[i, k] = z[i, k]
            rz += r[i, k] * z[i, k]
    thresh = tol * tol * max(bnorm, 1e-300)
    it = 0
    while it < max_iter:
        rr = 0.0
        for i in range(n):
            for k in range(3):
                rr += r[i, k] * r[i, k]
        if rr <= thresh:
            break
        _apply_system(p, diag, c_k, tets, dm_inv, vol, mu, lam, rots, anp, kappa_node, node_vol, theta_node,
                      eps_buf, free, ap)
        pap = 0.0
        for i in range(n):
            for k in range(3):
                pap += p[i, k] * ap[i, k]
        if pap <= 0.0:
            break
        alpha = rz / pap
        rz_new = 0.0
        for i in range(n):
            for k in range(3):
                x[i, k] += alpha * p[i, k]
                r[i, k] -= alpha * ap[i, k]
                z[i, k] = r[i, k] / precond[i]
                rz_new += r[i, k] * z[i, k]
        beta = rz_new / rz
        rz = rz_new
        for i in range(n):
            for k in range(3):
                p[i, k] = z[i, k] + beta * p[i, k]
        it += 1
    return it
