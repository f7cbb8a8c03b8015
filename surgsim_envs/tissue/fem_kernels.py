"""Numba kernels of the corotational linear tetrahedral FEM (hot loops only; see fem.py).

Per element e with rest edge-matrix inverse ``dm_inv`` (F = Ds Dm^-1) and rotation R_e the
stiffness product is ``P(y) = R K_e (R^T y - X)`` (``subtract_rest``) or ``R K_e R^T y``; it is
evaluated in tensor form: ``G = R^T (Ys Dm^-1)`` (minus I), ``eps = sym(G)``,
``sigma = 2 mu dev(eps) + p I`` with ``p = kappa tr(eps)`` (standard) or the averaged nodal
pressure (ANP), and nodal vectors ``V R sigma grad N_a``.  Elastic force = -P(x).
R is kept per tet as a matrix and refined by warm-started Newton steps applied as Cayley
rotations (:func:`update_rotations`). Every kernel that loops over elements comes single-thread
(loops with direct scatter) and threaded (``prange`` passes whose nodal sums are gathers over a
fixed node -> tet adjacency, :func:`make_work`, deterministic for any thread count): as two entry
points where the caller chooses in Python (``update_rotations``, ``elastic_energy``,
``symplectic_step``, ``stiffness_product_serial`` and their ``_parallel`` twins), so a
single-thread user never compiles the threaded passes; ``stiffness_product`` and the implicit
solve (``pcg_solve``) take a ``parallel`` argument and compile both.
Units: m, N, Pa, s.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


@njit(cache=True, inline="always", error_model="numpy")
def _edge_gradient(x, tets, dm_inv, e):
    """The 9 entries (row-major) of Xs Dm^-1 for tet e, Xs = [x_b - x_a, x_c - x_a, x_d - x_a]
    the edge matrix of positions ``x``: F at the current positions, or the displacement gradient
    for a displacement field."""
    a, b, c, d = tets[e, 0], tets[e, 1], tets[e, 2], tets[e, 3]
    m00, m01, m02 = dm_inv[e, 0, 0], dm_inv[e, 0, 1], dm_inv[e, 0, 2]
    m10, m11, m12 = dm_inv[e, 1, 0], dm_inv[e, 1, 1], dm_inv[e, 1, 2]
    m20, m21, m22 = dm_inv[e, 2, 0], dm_inv[e, 2, 1], dm_inv[e, 2, 2]
    d1, d2, d3 = x[b, 0] - x[a, 0], x[c, 0] - x[a, 0], x[d, 0] - x[a, 0]
    g00 = d1 * m00 + d2 * m10 + d3 * m20
    g01 = d1 * m01 + d2 * m11 + d3 * m21
    g02 = d1 * m02 + d2 * m12 + d3 * m22
    d1, d2, d3 = x[b, 1] - x[a, 1], x[c, 1] - x[a, 1], x[d, 1] - x[a, 1]
    g10 = d1 * m00 + d2 * m10 + d3 * m20
    g11 = d1 * m01 + d2 * m11 + d3 * m21
    g12 = d1 * m02 + d2 * m12 + d3 * m22
    d1, d2, d3 = x[b, 2] - x[a, 2], x[c, 2] - x[a, 2], x[d, 2] - x[a, 2]
    g20 = d1 * m00 + d2 * m10 + d3 * m20
    g21 = d1 * m01 + d2 * m11 + d3 * m21
    g22 = d1 * m02 + d2 * m12 + d3 * m22
    return g00, g01, g02, g10, g11, g12, g20, g21, g22


@njit(cache=True, inline="always", error_model="numpy")
def _element_rotation(x, tets, dm_inv, rots, e, max_iter, tol, eps, want_strain):
    """Polar rotation of tet e (see :func:`update_rotations`); updates rots[e] in place.
    With ``want_strain`` also writes the corotated strain sym(R^T F) - I into eps[e] (eps (T, 6))."""
    f00, f01, f02, f10, f11, f12, f20, f21, f22 = _edge_gradient(x, tets, dm_inv, e)
    _rotation_from_gradient(f00, f01, f02, f10, f11, f12, f20, f21, f22, rots, e, max_iter, tol, eps, want_strain)


@njit(cache=True, inline="always", error_model="numpy")
def _rotation_from_gradient(f00, f01, f02, f10, f11, f12, f20, f21, f22, rots, e, max_iter, tol, eps, want_strain):
    """:func:`_element_rotation` for tet e with its deformation gradient F (row-major) given."""
    r00, r01, r02 = rots[e, 0, 0], rots[e, 0, 1], rots[e, 0, 2]
    r10, r11, r12 = rots[e, 1, 0], rots[e, 1, 1], rots[e, 1, 2]
    r20, r21, r22 = rots[e, 2, 0], rots[e, 2, 1], rots[e, 2, 2]
    for it in range(max_iter):
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
            # Newton step w = N^-1 b = u / det with u = adj(N) b (no division yet)
            c11 = n00 * n22 - n02 * n02
            c12 = n01 * n02 - n00 * n12
            c22 = n00 * n11 - n01 * n01
            u0 = c00 * b0 + c01 * b1 + c02 * b2
            u1 = c01 * b0 + c11 * b1 + c12 * b2
            u2 = c02 * b0 + c12 * b1 + c22 * b2
        else:  # near-singular (inverted/degenerate): damped gradient step w = b / |tr|
            u0, u1, u2 = b0, b1, b2
            det = abs(tr) + 1e-9
        uu = u0 * u0 + u1 * u1 + u2 * u2
        dd = det * det
        if uu < tol * tol * dd:   # |w| < tol
            break
        if uu > dd:               # clamp |w| to 1 rad (inverted elements)
            sc = abs(det) / math.sqrt(uu)
            u0 *= sc
            u1 *= sc
            u2 *= sc
            uu = dd
        # R <- R C, C = Cayley(w/2) = I + k (W + W^2), W = [w/2]x, k = 2 / (1 + |w/2|^2): one division
        h = 1.0 / (4.0 * dd + uu)
        ka = 4.0 * det * h
        kb = 2.0 * h
        s0, s1, s2 = ka * u0, ka * u1, ka * u2
        p01, p02, p12 = kb * u0 * u1, kb * u0 * u2, kb * u1 * u2
        q0, q1, q2 = kb * u0 * u0, kb * u1 * u1, kb * u2 * u2
        k00 = 1.0 - q1 - q2
        k11 = 1.0 - q0 - q2
        k22 = 1.0 - q0 - q1
        k01, k10 = p01 - s2, p01 + s2
        k02, k20 = p02 + s1, p02 - s1
        k12, k21 = p12 - s0, p12 + s0
        t0 = r00 * k00 + r01 * k10 + r02 * k20
        t1 = r00 * k01 + r01 * k11 + r02 * k21
        r02 = r00 * k02 + r01 * k12 + r02 * k22
        r00, r01 = t0, t1
        t0 = r10 * k00 + r11 * k10 + r12 * k20
        t1 = r10 * k01 + r11 * k11 + r12 * k21
        r12 = r10 * k02 + r11 * k12 + r12 * k22
        r10, r11 = t0, t1
        t0 = r20 * k00 + r21 * k10 + r22 * k20
        t1 = r20 * k01 + r21 * k11 + r22 * k21
        r22 = r20 * k02 + r21 * k12 + r22 * k22
        r20, r21 = t0, t1
    rots[e, 0, 0], rots[e, 0, 1], rots[e, 0, 2] = r00, r01, r02
    rots[e, 1, 0], rots[e, 1, 1], rots[e, 1, 2] = r10, r11, r12
    rots[e, 2, 0], rots[e, 2, 1], rots[e, 2, 2] = r20, r21, r22
    if want_strain:
        eps[e, 0] = r00 * f00 + r10 * f10 + r20 * f20 - 1.0
        eps[e, 1] = r01 * f01 + r11 * f11 + r21 * f21 - 1.0
        eps[e, 2] = r02 * f02 + r12 * f12 + r22 * f22 - 1.0
        eps[e, 3] = 0.5 * (r00 * f01 + r10 * f11 + r20 * f21 + r01 * f00 + r11 * f10 + r21 * f20)
        eps[e, 4] = 0.5 * (r01 * f02 + r11 * f12 + r21 * f22 + r02 * f01 + r12 * f11 + r22 * f21)
        eps[e, 5] = 0.5 * (r02 * f00 + r12 * f10 + r22 * f20 + r00 * f02 + r10 * f12 + r20 * f22)


@njit(cache=True, error_model="numpy", parallel=True)
def update_rotations_parallel(x, tets, dm_inv, rots, max_iter, tol):
    """:func:`update_rotations` as a ``prange`` loop over the tets (the same result)."""
    eps = np.empty((1, 6))  # not written (want_strain=False)
    for e in prange(tets.shape[0]):
        _element_rotation(x, tets, dm_inv, rots, e, max_iter, tol, eps, False)


@njit(cache=True, error_model="numpy")
def update_rotations(x, tets, dm_inv, rots, max_iter, tol):
    """Rotation R of each tet's deformation gradient F = R S (polar decomposition).

    Newton iteration on the rotation, warm-started from ``rots`` (T, 3, 3), updated in place.
    With A = R^T F, S = sym(A), one step solves ``(tr(S) I - S) w = axial(A - A^T)`` and sets
    R <- R cay(w/2), the Cayley transform ``cay(v) = (I - [v]x)^-1 (I + [v]x)`` (exactly
    orthogonal; the rotation by angle 2 atan(|w|/2) about w, i.e. the quaternion update
    q <- q (x) (1, w/2); quadratic convergence; the fixed-rate variant of Mueller et al. 2016
    converges only by ~1/3 per iteration near S = I). The step costs one division: w = u/det
    with u = adj(N) b is never formed. Stops per element when |w| < ``tol`` rad or after
    ``max_iter`` iterations; with a warm start one iteration per time step suffices. Steps are
    clamped to 1 rad (inverted elements). Single thread; :func:`update_rotations_parallel` threads it.
    """
    eps = np.empty((1, 6))  # not written (want_strain=False)
    for e in range(tets.shape[0]):
        _element_rotation(x, tets, dm_inv, rots, e, max_iter, tol, eps, False)


@njit(cache=True, inline="always", error_model="numpy")
def _element_strain(y, tets, dm_inv, rots, e, subtract_rest, eps):
    """eps[e] (row of a (T, 6) array) = sym(R^T Ys Dm^-1) [- I], stored as xx, yy, zz, xy, yz, zx (tensor, not engineering)."""
    g00, g01, g02, g10, g11, g12, g20, g21, g22 = _edge_gradient(y, tets, dm_inv, e)   # g = Ys Dm^-1
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
    eps[e, 0] = h00 - off
    eps[e, 1] = h11 - off
    eps[e, 2] = h22 - off
    eps[e, 3] = 0.5 * (h01 + h10)
    eps[e, 4] = 0.5 * (h12 + h21)
    eps[e, 5] = 0.5 * (h20 + h02)


def make_work(tets: np.ndarray, n_nodes: int):
    """Work arrays of the element passes: ``(adj_ptr, adj_tet, adj_slot, eps (T,6), trv (T,),
    p_node (N,), fe (4T,3))``. The node -> incident-tet adjacency (CSR, ascending tet order) lets
    every nodal sum be a gather in a fixed order, so results do not depend on the thread count."""
    flat = np.ascontiguousarray(tets, dtype=np.int64).ravel()
    order = np.argsort(flat, kind="stable")
    ptr = np.zeros(n_nodes + 1, dtype=np.int64)
    np.add.at(ptr, flat + 1, 1)
    ptr = np.cumsum(ptr)
    nt = len(tets)
    return (ptr, (order // 4).astype(np.int64), order.astype(np.int64), np.zeros((nt, 6)), np.zeros(nt),
            np.zeros(n_nodes), np.zeros((4 * nt, 3)))


@njit(cache=True, error_model="numpy", parallel=True)
def _strain_pass(x_rot, y, fused, subtract_rest, tets, dm_inv, vol, rots, iters, tol, eps_buf, trv):
    """Per tet (parallel): rotation update (``iters`` > 0), corotated strain into eps_buf[e] and
    a quarter of its volume change into trv[e] (m^3)."""
    for e in prange(tets.shape[0]):
        if iters > 0:
            _element_rotation(x_rot, tets, dm_inv, rots, e, iters, tol, eps_buf, fused)
        if not fused:
            _element_strain(y, tets, dm_inv, rots, e, subtract_rest, eps_buf)
        trv[e] = 0.25 * vol[e] * (eps_buf[e, 0] + eps_buf[e, 1] + eps_buf[e, 2])


@njit(cache=True, error_model="numpy", parallel=True)
def _pressure_pass(adj_ptr, adj_tet, trv, kappa_node, node_vol, p_node):
    """Averaged nodal pressure (Pa, parallel over nodes): p_a = kappa_a sum_e trv_e / V_a."""
    for n in prange(p_node.shape[0]):
        th = 0.0
        for k in range(adj_ptr[n], adj_ptr[n + 1]):
            th += trv[adj_tet[k]]
        p_node[n] = kappa_node[n] * th / node_vol[n]


@njit(cache=True, error_model="numpy", parallel=True)
def _force_pass(tets, dm_inv, vol, mu, lam, rots, anp, p_node, eps_buf, fe):
    """Per tet (parallel): stress from eps_buf and nodal vectors V R sigma grad N_a into fe[4e + a]."""
    for e in prange(tets.shape[0]):
        e0, e1, e2 = eps_buf[e, 0], eps_buf[e, 1], eps_buf[e, 2]
        tr = e0 + e1 + e2
        m2 = 2.0 * mu[e]
        if anp:
            iso = 0.25 * (p_node[tets[e, 0]] + p_node[tets[e, 1]] + p_node[tets[e, 2]] + p_node[tets[e, 3]]) \
                - m2 * tr / 3.0
        else:
            iso = lam[e] * tr
        v = vol[e]
        s0 = v * (m2 * e0 + iso)
        s1 = v * (m2 * e1 + iso)
        s2 = v * (m2 * e2 + iso)
        s3 = v * m2 * eps_buf[e, 3]
        s4 = v * m2 * eps_buf[e, 4]
        s5 = v * m2 * eps_buf[e, 5]
        for i in range(3):  # row i of P = R (V sigma)
            r0, r1, r2 = rots[e, i, 0], rots[e, i, 1], rots[e, i, 2]
            p0 = r0 * s0 + r1 * s3 + r2 * s5
            p1 = r0 * s3 + r1 * s1 + r2 * s4
            p2 = r0 * s5 + r1 * s4 + r2 * s2
            f1 = p0 * dm_inv[e, 0, 0] + p1 * dm_inv[e, 0, 1] + p2 * dm_inv[e, 0, 2]
            f2 = p0 * dm_inv[e, 1, 0] + p1 * dm_inv[e, 1, 1] + p2 * dm_inv[e, 1, 2]
            f3 = p0 * dm_inv[e, 2, 0] + p1 * dm_inv[e, 2, 1] + p2 * dm_inv[e, 2, 2]
            fe[4 * e, i] = -(f1 + f2 + f3)
            fe[4 * e + 1, i] = f1
            fe[4 * e + 2, i] = f2
            fe[4 * e + 3, i] = f3


@njit(cache=True, error_model="numpy", parallel=True)
def _gather_pass(adj_ptr, adj_slot, fe, out):
    """out[n] = sum of the element vectors of node n (parallel over nodes, fixed order)."""
    for n in prange(out.shape[0]):
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        for k in range(adj_ptr[n], adj_ptr[n + 1]):
            s = adj_slot[k]
            f0 += fe[s, 0]
            f1 += fe[s, 1]
            f2 += fe[s, 2]
        out[n, 0] = f0
        out[n, 1] = f1
        out[n, 2] = f2


@njit(cache=True, error_model="numpy")
def _element_vectors(y, tets, dm_inv, vol, mu, lam, rots, subtract_rest, anp, kappa_node, node_vol, work,
                     x_rot, rot_iters, rot_tol, y_is_x_rot):
    """Strain, pressure and force passes of :func:`stiffness_product`; leaves the per-tet nodal
    vectors in work[6] (fe)."""
    adj_ptr, adj_tet, adj_slot, eps_buf, trv, p_node, fe = work
    fused = rot_iters > 0 and subtract_rest and y_is_x_rot  # strain comes out of the rotation update
    _strain_pass(x_rot, y, fused, subtract_rest, tets, dm_inv, vol, rots, rot_iters, rot_tol, eps_buf, trv)
    if anp:
        _pressure_pass(adj_ptr, adj_tet, trv, kappa_node, node_vol, p_node)
    _force_pass(tets, dm_inv, vol, mu, lam, rots, anp, p_node, eps_buf, fe)


@njit(cache=True, inline="always", error_model="numpy")
def _scatter_stress(tets, dm_inv, vol, rots, e, s0, s1, s2, s3, s4, s5, out):
    """out[node] += V R sigma grad N for tet e (sigma symmetric: xx, yy, zz, xy, yz, zx)."""
    v = vol[e]
    s0, s1, s2, s3, s4, s5 = v * s0, v * s1, v * s2, v * s3, v * s4, v * s5
    a, b, c, d = tets[e, 0], tets[e, 1], tets[e, 2], tets[e, 3]
    for i in range(3):  # row i of P = R (V sigma)
        r0, r1, r2 = rots[e, i, 0], rots[e, i, 1], rots[e, i, 2]
        p0 = r0 * s0 + r1 * s3 + r2 * s5
        p1 = r0 * s3 + r1 * s1 + r2 * s4
        p2 = r0 * s5 + r1 * s4 + r2 * s2
        f1 = p0 * dm_inv[e, 0, 0] + p1 * dm_inv[e, 0, 1] + p2 * dm_inv[e, 0, 2]
        f2 = p0 * dm_inv[e, 1, 0] + p1 * dm_inv[e, 1, 1] + p2 * dm_inv[e, 1, 2]
        f3 = p0 * dm_inv[e, 2, 0] + p1 * dm_inv[e, 2, 1] + p2 * dm_inv[e, 2, 2]
        out[b, i] += f1
        out[c, i] += f2
        out[d, i] += f3
        out[a, i] -= f1 + f2 + f3


@njit(cache=True, error_model="numpy")
def _serial_product(y, tets, dm_inv, vol, mu, lam, rots, subtract_rest, anp, kappa_node, node_vol, work, out,
                    x_rot, rot_iters, rot_tol, y_is_x_rot):
    """Single-thread :func:`stiffness_product`: two element loops with direct scatter (the
    rotation update, strain and nodal volume change fused into the first)."""
    eps = work[3]
    theta = work[5]
    fused = rot_iters > 0 and subtract_rest and y_is_x_rot
    out[:] = 0.0
    nt = tets.shape[0]
    if anp:
        theta[:] = 0.0
    for e in range(nt):
        if rot_iters > 0:
            _element_rotation(x_rot, tets, dm_inv, rots, e, rot_iters, rot_tol, eps, fused)
        if not fused:
            _element_strain(y, tets, dm_inv, rots, e, subtract_rest, eps)
        if anp:
            q = 0.25 * vol[e] * (eps[e, 0] + eps[e, 1] + eps[e, 2])
            for k in range(4):
                theta[tets[e, k]] += q
        else:  # standard: stress is local, scatter right away
            tr = eps[e, 0] + eps[e, 1] + eps[e, 2]
            m2 = 2.0 * mu[e]
            lt = lam[e] * tr
            _scatter_stress(tets, dm_inv, vol, rots, e, m2 * eps[e, 0] + lt, m2 * eps[e, 1] + lt,
                            m2 * eps[e, 2] + lt, m2 * eps[e, 3], m2 * eps[e, 4], m2 * eps[e, 5], out)
    if not anp:
        return
    for a in range(theta.shape[0]):  # nodal pressure p_a = kappa_a theta_a / V_a
        theta[a] = kappa_node[a] * theta[a] / node_vol[a]
    for e in range(nt):
        pbar = 0.25 * (theta[tets[e, 0]] + theta[tets[e, 1]] + theta[tets[e, 2]] + theta[tets[e, 3]])
        m2 = 2.0 * mu[e]
        iso = pbar - m2 * (eps[e, 0] + eps[e, 1] + eps[e, 2]) / 3.0
        _scatter_stress(tets, dm_inv, vol, rots, e, m2 * eps[e, 0] + iso, m2 * eps[e, 1] + iso,
                        m2 * eps[e, 2] + iso, m2 * eps[e, 3], m2 * eps[e, 4], m2 * eps[e, 5], out)


@njit(cache=True, error_model="numpy")
def stiffness_product(y, tets, dm_inv, vol, mu, lam, rots, subtract_rest, anp, kappa_node, node_vol,
                      work, out, x_rot, rot_iters, rot_tol, y_is_x_rot, parallel):
    """out (N,3) = R K R^T y - [R K X]: the (warped) stiffness applied to y (N/m * m = N).

    With ``subtract_rest`` this is minus the elastic force at positions y. ``anp`` selects the
    averaged-nodal-pressure volumetric term (``kappa_node``, ``node_vol`` per node); otherwise
    each tet uses its own lambda. ``work`` comes from :func:`make_work`. With ``rot_iters`` > 0
    the rotations are first updated from ``x_rot`` (in the same pass; ``y_is_x_rot`` says y and
    x_rot are the same positions so the strain comes for free).

    ``parallel``: four passes, each a ``prange`` loop free of write conflicts (per tet rotation +
    strain; per node averaged pressure, a gather; per tet stress -> nodal vectors; per node sum,
    a gather), so the result does not depend on the thread count. Otherwise a single-thread
    version with two loops and direct scatter (fastest on one core).
    """
    if not parallel:
        _serial_product(y, tets, dm_inv, vol, mu, lam, rots, subtract_rest, anp, kappa_node, node_vol, work, out,
                        x_rot, rot_iters, rot_tol, y_is_x_rot)
        return
    stiffness_product_parallel(y, tets, dm_inv, vol, mu, lam, rots, subtract_rest, anp, kappa_node, node_vol,
                               work, out, x_rot, rot_iters, rot_tol, y_is_x_rot)


@njit(cache=True, error_model="numpy")
def stiffness_product_serial(y, tets, dm_inv, vol, mu, lam, rots, subtract_rest, anp, kappa_node, node_vol,
                             work, out, x_rot, rot_iters, rot_tol, y_is_x_rot):
    """:func:`stiffness_product` on one thread: the entry point a single-thread caller takes from
    Python, which then never compiles the threaded passes."""
    _serial_product(y, tets, dm_inv, vol, mu, lam, rots, subtract_rest, anp, kappa_node, node_vol, work, out,
                    x_rot, rot_iters, rot_tol, y_is_x_rot)


@njit(cache=True, error_model="numpy")
def stiffness_product_parallel(y, tets, dm_inv, vol, mu, lam, rots, subtract_rest, anp, kappa_node, node_vol,
                               work, out, x_rot, rot_iters, rot_tol, y_is_x_rot):
    """:func:`stiffness_product` as ``prange`` passes (the same result)."""
    _element_vectors(y, tets, dm_inv, vol, mu, lam, rots, subtract_rest, anp, kappa_node, node_vol, work,
                     x_rot, rot_iters, rot_tol, y_is_x_rot)
    _gather_pass(work[0], work[2], work[6], out)


@njit(cache=True, error_model="numpy", parallel=True)
def _integrate_pass(adj_ptr, adj_slot, fe, x, v, fext, masses, alpha, gravity, fixed, dt):
    """Symplectic Euler update per node (parallel), elastic force = -(gathered element vectors)."""
    for n in prange(x.shape[0]):
        if fixed[n]:
            v[n, 0] = 0.0
            v[n, 1] = 0.0
            v[n, 2] = 0.0
            continue
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        for k in range(adj_ptr[n], adj_ptr[n + 1]):
            s = adj_slot[k]
            f0 += fe[s, 0]
            f1 += fe[s, 1]
            f2 += fe[s, 2]
        inv_m = 1.0 / masses[n]
        damp = 1.0 / (1.0 + alpha[n] * dt)
        v[n, 0] = (v[n, 0] + dt * ((fext[n, 0] - f0) * inv_m + gravity[0])) * damp
        v[n, 1] = (v[n, 1] + dt * ((fext[n, 1] - f1) * inv_m + gravity[1])) * damp
        v[n, 2] = (v[n, 2] + dt * ((fext[n, 2] - f2) * inv_m + gravity[2])) * damp
        x[n, 0] += dt * v[n, 0]
        x[n, 1] += dt * v[n, 1]
        x[n, 2] += dt * v[n, 2]


@njit(cache=True, error_model="numpy", parallel=True)
def _energy_pass(x, tets, dm_inv, vol, mu, lam, rots, anp, rot_iters, rot_tol, eps_buf, trv, e_tet):
    """Per tet (parallel): rotation update (``rot_iters`` > 0, to ``rot_tol`` rad), strain,
    deviatoric (anp) or full energy into e_tet[e] (J), a quarter of the volume change into trv[e]."""
    for e in prange(tets.shape[0]):
        if rot_iters > 0:
            _element_rotation(x, tets, dm_inv, rots, e, rot_iters, rot_tol, eps_buf, True)
        else:
            _element_strain(x, tets, dm_inv, rots, e, True, eps_buf)
        e0, e1, e2, e3, e4, e5 = eps_buf[e, 0], eps_buf[e, 1], eps_buf[e, 2], eps_buf[e, 3], eps_buf[e, 4], eps_buf[e, 5]
        tr = e0 + e1 + e2
        ee = e0 * e0 + e1 * e1 + e2 * e2 + 2.0 * (e3 * e3 + e4 * e4 + e5 * e5)
        if anp:
            e_tet[e] = vol[e] * mu[e] * (ee - tr * tr / 3.0)
        else:
            e_tet[e] = vol[e] * (mu[e] * ee + 0.5 * lam[e] * tr * tr)
        trv[e] = 0.25 * vol[e] * tr


@njit(cache=True, error_model="numpy")
def _energy_serial(x, tets, dm_inv, vol, mu, lam, rots, anp, rot_iters, rot_tol, eps_buf, trv, e_tet):
    """Single-thread :func:`_energy_pass` (same loop body, written out on purpose: a per-tet
    helper call is not inlined and costs 5x, and even an ``inline="always"`` helper made
    ``elastic_energy`` 1.6-2.5x slower on 3,969 nodes)."""
    for e in range(tets.shape[0]):
        if rot_iters > 0:
            _element_rotation(x, tets, dm_inv, rots, e, rot_iters, rot_tol, eps_buf, True)
        else:
            _element_strain(x, tets, dm_inv, rots, e, True, eps_buf)
        e0, e1, e2, e3, e4, e5 = eps_buf[e, 0], eps_buf[e, 1], eps_buf[e, 2], eps_buf[e, 3], eps_buf[e, 4], eps_buf[e, 5]
        tr = e0 + e1 + e2
        ee = e0 * e0 + e1 * e1 + e2 * e2 + 2.0 * (e3 * e3 + e4 * e4 + e5 * e5)
        if anp:
            e_tet[e] = vol[e] * mu[e] * (ee - tr * tr / 3.0)
        else:
            e_tet[e] = vol[e] * (mu[e] * ee + 0.5 * lam[e] * tr * tr)
        trv[e] = 0.25 * vol[e] * tr


@njit(cache=True, error_model="numpy")
def elastic_energy(x, tets, dm_inv, vol, mu, lam, rots, anp, kappa_node, node_vol, rot_iters, rot_tol, work):
    """Stored energy (J) of the (corotated) linear material at positions x. With ``rot_iters`` > 0
    the rotations are first brought to ``rot_tol`` rad at x (same pass). Sums in a fixed order.
    Single thread; :func:`elastic_energy_parallel` threads the element pass (the same result)."""
    adj_ptr, adj_tet, adj_slot, eps_buf, trv, p_node, fe = work
    e_tet = fe[:, 0]  # scratch (4T >= T entries)
    _energy_serial(x, tets, dm_inv, vol, mu, lam, rots, anp, rot_iters, rot_tol, eps_buf, trv, e_tet)
    return _energy_sum(tets, anp, kappa_node, node_vol, adj_ptr, adj_tet, trv, e_tet)


@njit(cache=True, error_model="numpy")
def elastic_energy_parallel(x, tets, dm_inv, vol, mu, lam, rots, anp, kappa_node, node_vol, rot_iters, rot_tol, work):
    """:func:`elastic_energy` with the element pass as a ``prange`` loop. A separate entry point,
    not a flag: a kernel that branches on a run-time flag compiles both passes, and the threaded
    one (about 12 s of first-use compile here) is then built for single-thread users too."""
    adj_ptr, adj_tet, adj_slot, eps_buf, trv, p_node, fe = work
    e_tet = fe[:, 0]
    _energy_pass(x, tets, dm_inv, vol, mu, lam, rots, anp, rot_iters, rot_tol, eps_buf, trv, e_tet)
    return _energy_sum(tets, anp, kappa_node, node_vol, adj_ptr, adj_tet, trv, e_tet)


@njit(cache=True, error_model="numpy")
def _energy_sum(tets, anp, kappa_node, node_vol, adj_ptr, adj_tet, trv, e_tet):
    """The per-tet energies plus (anp) the nodal pressure energy, J, summed in a fixed order."""
    energy = 0.0
    for e in range(tets.shape[0]):
        energy += e_tet[e]
    if anp:
        for a in range(node_vol.shape[0]):
            th = 0.0
            for k in range(adj_ptr[a], adj_ptr[a + 1]):
                th += trv[adj_tet[k]]
            th /= node_vol[a]
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
def _damped_positions(x, v, beta, y_buf):
    """The positions the stiffness product sees: x, or x + beta v (Rayleigh damping) in ``y_buf``."""
    if beta > 0.0:
        for i in range(x.shape[0]):
            for k in range(3):
                y_buf[i, k] = x[i, k] + beta * v[i, k]
        return y_buf
    return x


@njit(cache=True, error_model="numpy")
def symplectic_step(x, v, fext, masses, alpha, gravity, fixed, dt, beta, corotational, rot_iters, rot_tol,
                    tets, dm_inv, vol, mu, lam, rots, anp, kappa_node, node_vol, work, y_buf, f_buf):
    """One semi-implicit (symplectic) Euler step in place, single thread.

    v += dt (f_el(x, v) + f_ext + m g) / m, then mass damping v /= (1 + alpha dt), then x += dt v.
    Stiffness (Rayleigh) damping beta K v enters as the stiffness product of x + beta v.
    The rotation update is fused into the strain loop. :func:`symplectic_step_parallel` is the
    threaded twin (a separate entry point: a run-time flag would compile both for every caller).
    """
    iters = rot_iters if corotational else 0
    y = _damped_positions(x, v, beta, y_buf)
    # np.bool_ / np.int64, not a literal constant: a literal compiles the callee a second time (numba
    # specialises on literal arguments), seconds to tens of seconds of first-use compile for nothing
    _serial_product(y, tets, dm_inv, vol, mu, lam, rots, np.bool_(True), anp, kappa_node, node_vol, work, f_buf,
                    x, iters, rot_tol, beta <= 0.0)
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
def symplectic_step_parallel(x, v, fext, masses, alpha, gravity, fixed, dt, beta, corotational, rot_iters, rot_tol,
                             tets, dm_inv, vol, mu, lam, rots, anp, kappa_node, node_vol, work, y_buf, f_buf):
    """:func:`symplectic_step` with ``prange`` passes, the force gather fused into the (parallel)
    nodal update; the same result."""
    iters = rot_iters if corotational else 0
    y = _damped_positions(x, v, beta, y_buf)
    _element_vectors(y, tets, dm_inv, vol, mu, lam, rots, np.bool_(True), anp, kappa_node, node_vol, work,
                     x, iters, rot_tol, beta <= 0.0)
    _integrate_pass(work[0], work[2], work[6], x, v, fext, masses, alpha, gravity, fixed, dt)


@njit(cache=True, error_model="numpy")
def apply_system(y, diag, c_k, tets, dm_inv, vol, mu, lam, rots, anp, kappa_node, node_vol, work, free, out,
                  parallel):
    """out = (diag + c_k R K R^T) y on free DOFs (zero rows/cols at fixed nodes)."""
    # np.bool_ / np.int64, not a literal constant: a literal compiles the callee a second time (numba
    # specialises on literal arguments), seconds to tens of seconds of first-use compile for nothing
    stiffness_product(y, tets, dm_inv, vol, mu, lam, rots, np.bool_(False), anp, kappa_node, node_vol, work, out,
                      y, np.int64(0), 0.0, np.bool_(False), parallel)
    for i in range(y.shape[0]):
        if free[i]:
            for k in range(3):
                out[i, k] = diag[i] * y[i, k] + c_k * out[i, k]
        else:
            for k in range(3):
                out[i, k] = 0.0


@njit(cache=True, error_model="numpy")
def pcg_solve(rhs, x, diag, c_k, precond, free, tol, max_iter, tets, dm_inv, vol, mu, lam, rots, anp,
              kappa_node, node_vol, work, parallel):
    """Jacobi-preconditioned CG for (diag M' + c_k R K R^T) x = rhs on free nodes; x is the initial
    guess (values at fixed nodes are held, i.e. must be zero). Returns the iteration count."""
    n = rhs.shape[0]
    r = np.empty((n, 3))
    z = np.empty((n, 3))
    p = np.empty((n, 3))
    ap = np.empty((n, 3))
    apply_system(x, diag, c_k, tets, dm_inv, vol, mu, lam, rots, anp, kappa_node, node_vol, work, free, ap, parallel)
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
        apply_system(p, diag, c_k, tets, dm_inv, vol, mu, lam, rots, anp, kappa_node, node_vol, work, free, ap, parallel)
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

