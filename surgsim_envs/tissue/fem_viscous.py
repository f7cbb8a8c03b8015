"""Standard-linear-solid (one-term Prony) branch per element of the tetrahedral FEM.

Per element ``e`` with relax fraction ``g`` and time ``tau`` (material ``relax_fraction`` /
``relax_time``), the corotated Cauchy stress is (Simo's hereditary-integral form)

    sigma(t) = (1 - g) sigma0(t) + g h(t),    h(t) = int_0^t exp(-(t - s)/tau) d sigma0(s)

with ``sigma0`` the instantaneous elastic stress (modulus E, corotated frame, ANP pressure
included). A held strain relaxes the stress from ``sigma0`` to ``(1 - g) sigma0`` with time
constant ``tau``, exactly as each mass-spring spring does (the grasping simulation paper eq. 3). Over a step of ``h`` s
with ``sigma0`` varying linearly the update is exact:

    h_{n+1} = exp(-h/tau) h_n + gamma (sigma0_{n+1} - sigma0_n),   gamma = tau/h (1 - exp(-h/tau)).

So the stress at the end of a step is ``c sigma0_{n+1} + g (exp(-h/tau) h_n - gamma sigma0_n)``,
``c = 1 - g + g gamma``: an elastic element with moduli scaled by ``c`` plus a constant corotated
stress, which the implicit solve treats exactly (see :class:`~surgsim_envs.tissue.fem.TetFEMModel`).
Units: Pa, s, m, N.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from surgsim_envs.tissue.fem_kernels import _edge_gradient, _element_strain, _rotation_from_gradient, _scatter_stress


def branch_coefficients(h: float, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(decay exp(-h/tau), gamma = tau/h (1 - exp(-h/tau))) per element; (1, 1) for h = 0."""
    if h <= 0:
        return np.ones_like(tau), np.ones_like(tau)
    x = h / tau
    decay = np.exp(-x)
    gamma = np.where(x > 1e-12, -np.expm1(-x) / np.where(x > 1e-12, x, 1.0), 1.0 - 0.5 * x)
    return decay, gamma


@njit(cache=True, nogil=True)
def corotated_stress(x, tets, dm_inv, vol, rots, mu, lam, anp, kappa_node, node_vol, trv, p_node, out):
    """Instantaneous corotated stress (T,3,3) Pa at positions x with element rotations ``rots``:
    ``2 mu dev(eps) + p I`` with the averaged nodal pressure ``p`` (ANP) or ``2 mu eps + lam tr(eps) I``;
    eps = sym(R^T Ds Dm^-1) - I. ``trv`` (T,) and ``p_node`` (N,) are work buffers."""
    nt = tets.shape[0]
    f = np.empty((3, 3))
    for e in range(nt):
        a0 = tets[e, 0]
        for i in range(3):
            for j in range(3):
                s = 0.0
                for k in range(3):
                    # (R^T Ds)_ik = sum_m R_mi (x[t_k+1] - x[t_0])_m
                    ds = 0.0
                    for m in range(3):
                        ds += rots[e, m, i] * (x[tets[e, k + 1], m] - x[a0, m])
                    s += ds * dm_inv[e, k, j]
                f[i, j] = s
        tr = f[0, 0] + f[1, 1] + f[2, 2] - 3.0
        trv[e] = tr
        for i in range(3):
            for j in range(3):
                eps = 0.5 * (f[i, j] + f[j, i]) - (1.0 if i == j else 0.0)
                out[e, i, j] = 2.0 * mu[e] * eps
    if anp:
        p_node[:] = 0.0
        for e in range(nt):
            for q in range(4):
                p_node[tets[e, q]] += 0.25 * vol[e] * trv[e]
        for a in range(p_node.shape[0]):
            p_node[a] = kappa_node[a] * p_node[a] / node_vol[a]
        for e in range(nt):
            p = 0.25 * (p_node[tets[e, 0]] + p_node[tets[e, 1]] + p_node[tets[e, 2]] + p_node[tets[e, 3]])
            d = 2.0 * mu[e] * trv[e] / 3.0
            for i in range(3):
                out[e, i, i] += p - d
    else:
        for e in range(nt):
            for i in range(3):
                out[e, i, i] += lam[e] * trv[e]


@njit(cache=True, nogil=True)
def add_stress_forces(tets, grads, vol, rots, stress, out):
    """out[a] -= V_e R_e stress_e grad N_a for every element e and its four nodes a (N): the nodal
    forces of a corotated element stress (T,3,3) Pa. They sum to zero per element."""
    for e in range(tets.shape[0]):
        for q in range(4):
            a = tets[e, q]
            for i in range(3):
                acc = 0.0
                for j in range(3):
                    sg = 0.0
                    for k in range(3):
                        sg += stress[e, j, k] * grads[e, q, k]
                    acc += rots[e, i, j] * sg
                out[a, i] -= vol[e] * acc


@njit(cache=True, inline="always", error_model="numpy")
def _branch_element(e, s0, s1, s2, s3, s4, s5, g, decay, gamma, h, sig_prev):
    """Advance tet e's branch to an instantaneous stress ``s0..s5`` (xx, yy, zz, xy, yz, zx; Pa):
    h <- decay h + gamma (sigma0 - sigma_prev), sigma_prev <- sigma0 (both kept as full symmetric
    (3,3) blocks); returns the excess stress g (h - sigma0) in the same order."""
    ge = g[e]
    de = decay[e]
    ga = gamma[e]
    h0 = de * h[e, 0, 0] + ga * (s0 - sig_prev[e, 0, 0])
    h1 = de * h[e, 1, 1] + ga * (s1 - sig_prev[e, 1, 1])
    h2 = de * h[e, 2, 2] + ga * (s2 - sig_prev[e, 2, 2])
    h3 = de * h[e, 0, 1] + ga * (s3 - sig_prev[e, 0, 1])
    h4 = de * h[e, 1, 2] + ga * (s4 - sig_prev[e, 1, 2])
    h5 = de * h[e, 2, 0] + ga * (s5 - sig_prev[e, 2, 0])
    h[e, 0, 0] = h0
    h[e, 1, 1] = h1
    h[e, 2, 2] = h2
    h[e, 0, 1] = h3
    h[e, 1, 0] = h3
    h[e, 1, 2] = h4
    h[e, 2, 1] = h4
    h[e, 2, 0] = h5
    h[e, 0, 2] = h5
    sig_prev[e, 0, 0] = s0
    sig_prev[e, 1, 1] = s1
    sig_prev[e, 2, 2] = s2
    sig_prev[e, 0, 1] = s3
    sig_prev[e, 1, 0] = s3
    sig_prev[e, 1, 2] = s4
    sig_prev[e, 2, 1] = s4
    sig_prev[e, 2, 0] = s5
    sig_prev[e, 0, 2] = s5
    return ge * (h0 - s0), ge * (h1 - s1), ge * (h2 - s2), ge * (h3 - s3), ge * (h4 - s4), ge * (h5 - s5)


@njit(cache=True, inline="always", error_model="numpy")
def _scatter_two_stresses(tets, dm_inv, vol, rots_a, rots_b, e, a0, a1, a2, a3, a4, a5, b0, b1, b2, b3, b4, b5, out):
    """out[node] += V (R_a sigma_a + R_b sigma_b) grad N for tet e, one update per node and component
    (each sigma symmetric: xx, yy, zz, xy, yz, zx; rotations ``rots_a[e]``, ``rots_b[e]``)."""
    v = vol[e]
    a0, a1, a2, a3, a4, a5 = v * a0, v * a1, v * a2, v * a3, v * a4, v * a5
    b0, b1, b2, b3, b4, b5 = v * b0, v * b1, v * b2, v * b3, v * b4, v * b5
    ta, tb, tc, td = tets[e, 0], tets[e, 1], tets[e, 2], tets[e, 3]
    for i in range(3):  # row i of P = R_a (V sigma_a) + R_b (V sigma_b)
        r0, r1, r2 = rots_a[e, i, 0], rots_a[e, i, 1], rots_a[e, i, 2]
        q0, q1, q2 = rots_b[e, i, 0], rots_b[e, i, 1], rots_b[e, i, 2]
        p0 = r0 * a0 + r1 * a3 + r2 * a5 + q0 * b0 + q1 * b3 + q2 * b5
        p1 = r0 * a3 + r1 * a1 + r2 * a4 + q0 * b3 + q1 * b1 + q2 * b4
        p2 = r0 * a5 + r1 * a4 + r2 * a2 + q0 * b5 + q1 * b4 + q2 * b2
        f1 = p0 * dm_inv[e, 0, 0] + p1 * dm_inv[e, 0, 1] + p2 * dm_inv[e, 0, 2]
        f2 = p0 * dm_inv[e, 1, 0] + p1 * dm_inv[e, 1, 1] + p2 * dm_inv[e, 1, 2]
        f3 = p0 * dm_inv[e, 2, 0] + p1 * dm_inv[e, 2, 1] + p2 * dm_inv[e, 2, 2]
        out[tb, i] += f1
        out[tc, i] += f2
        out[td, i] += f3
        out[ta, i] -= f1 + f2 + f3


@njit(cache=True, error_model="numpy")
def symplectic_step(x, v, fext, masses, alpha, gravity, fixed, dt, beta, corotational, rot_iters, rot_tol,
                    tets, dm_inv, vol, mu, lam, rots, anp, kappa_node, node_vol, work, y_buf, f_buf,
                    g, decay, gamma, h, sig_prev, eps_old, theta_old, rots_old):
    """One semi-implicit Euler step of the viscoelastic FEM in place, single thread: the branches
    committed at x_n and the elastic force in the same element passes.

    The same step as committing the branches (:func:`corotated_stress` with the rotations before
    this step's update, then ``h`` and ``sig_prev`` advanced with ``decay``/``gamma`` of the interval
    since the last commit), adding the excess stress g (h_n - sigma0_n) as element forces
    (:func:`add_stress_forces`) and calling :func:`surgsim_envs.tissue.fem_kernels.symplectic_step`
    with ``parallel`` False. Fused, every tet is read twice instead of six times: the first loop
    forms the deformation gradient once, takes from it the instantaneous strain with the old
    rotation (kept in ``rots_old`` (T,3,3)), updates the rotation and takes the elastic strain; the second forms both stresses, advances the
    branch and scatters both force sets. Only the order of floating-point sums differs from the
    unfused sequence. Work buffers: ``eps_old`` (T,6), ``theta_old`` (N,); ``g``, ``decay``,
    ``gamma`` (T,); ``h``, ``sig_prev`` (T,3,3) Pa, updated in place.
    """
    iters = rot_iters if corotational else 0
    y = x
    if beta > 0.0:
        for i in range(x.shape[0]):
            for k in range(3):
                y_buf[i, k] = x[i, k] + beta * v[i, k]
        y = y_buf
    fused = iters > 0 and beta <= 0.0     # the elastic strain comes out of the rotation update
    eps = work[3]
    theta = work[5]
    out = f_buf
    out[:] = 0.0
    nt = tets.shape[0]
    if anp:
        theta[:] = 0.0
        theta_old[:] = 0.0
    for e in range(nt):
        f00, f01, f02, f10, f11, f12, f20, f21, f22 = _edge_gradient(x, tets, dm_inv, e)
        r00, r01, r02 = rots[e, 0, 0], rots[e, 0, 1], rots[e, 0, 2]
        r10, r11, r12 = rots[e, 1, 0], rots[e, 1, 1], rots[e, 1, 2]
        r20, r21, r22 = rots[e, 2, 0], rots[e, 2, 1], rots[e, 2, 2]
        rots_old[e, 0, 0], rots_old[e, 0, 1], rots_old[e, 0, 2] = r00, r01, r02
        rots_old[e, 1, 0], rots_old[e, 1, 1], rots_old[e, 1, 2] = r10, r11, r12
        rots_old[e, 2, 0], rots_old[e, 2, 1], rots_old[e, 2, 2] = r20, r21, r22
        # sigma0_n's strain sym(R^T F) - I with the rotations of x_{n-1} (as _element_strain)
        h00 = r00 * f00 + r10 * f10 + r20 * f20
        h11 = r01 * f01 + r11 * f11 + r21 * f21
        h22 = r02 * f02 + r12 * f12 + r22 * f22
        h01 = r00 * f01 + r10 * f11 + r20 * f21
        h10 = r01 * f00 + r11 * f10 + r21 * f20
        h12 = r01 * f02 + r11 * f12 + r21 * f22
        h21 = r02 * f01 + r12 * f11 + r22 * f21
        h20 = r02 * f00 + r12 * f10 + r22 * f20
        h02 = r00 * f02 + r10 * f12 + r20 * f22
        eps_old[e, 0] = h00 - 1.0
        eps_old[e, 1] = h11 - 1.0
        eps_old[e, 2] = h22 - 1.0
        eps_old[e, 3] = 0.5 * (h01 + h10)
        eps_old[e, 4] = 0.5 * (h12 + h21)
        eps_old[e, 5] = 0.5 * (h20 + h02)
        if iters > 0:
            _rotation_from_gradient(f00, f01, f02, f10, f11, f12, f20, f21, f22, rots, e, iters, rot_tol, eps, fused)
        if not fused:
            _element_strain(y, tets, dm_inv, rots, e, True, eps)
        if anp:
            qo = 0.25 * vol[e] * (eps_old[e, 0] + eps_old[e, 1] + eps_old[e, 2])
            q = 0.25 * vol[e] * (eps[e, 0] + eps[e, 1] + eps[e, 2])
            for k in range(4):
                theta_old[tets[e, k]] += qo
                theta[tets[e, k]] += q
    if anp:
        for a in range(theta.shape[0]):   # nodal pressures p_a = kappa_a theta_a / V_a
            theta[a] = kappa_node[a] * theta[a] / node_vol[a]
            theta_old[a] = kappa_node[a] * theta_old[a] / node_vol[a]
    for e in range(nt):
        m2 = 2.0 * mu[e]
        o0, o1, o2 = eps_old[e, 0], eps_old[e, 1], eps_old[e, 2]
        tro = o0 + o1 + o2
        tr = eps[e, 0] + eps[e, 1] + eps[e, 2]
        if anp:
            t0, t1, t2, t3 = tets[e, 0], tets[e, 1], tets[e, 2], tets[e, 3]
            iso_o = 0.25 * (theta_old[t0] + theta_old[t1] + theta_old[t2] + theta_old[t3]) - m2 * tro / 3.0
            iso = 0.25 * (theta[t0] + theta[t1] + theta[t2] + theta[t3]) - m2 * tr / 3.0
        else:
            iso_o = lam[e] * tro
            iso = lam[e] * tr
        x0, x1, x2, x3, x4, x5 = _branch_element(e, m2 * o0 + iso_o, m2 * o1 + iso_o, m2 * o2 + iso_o,
                                                 m2 * eps_old[e, 3], m2 * eps_old[e, 4], m2 * eps_old[e, 5],
                                                 g, decay, gamma, h, sig_prev)
        _scatter_two_stresses(tets, dm_inv, vol, rots_old, rots, e, x0, x1, x2, x3, x4, x5, m2 * eps[e, 0] + iso,
                              m2 * eps[e, 1] + iso, m2 * eps[e, 2] + iso, m2 * eps[e, 3], m2 * eps[e, 4],
                              m2 * eps[e, 5], out)
    for i in range(x.shape[0]):
        if fixed[i]:
            for k in range(3):
                v[i, k] = 0.0
            continue
        inv_m = 1.0 / masses[i]
        damp = 1.0 / (1.0 + alpha[i] * dt)
        for k in range(3):
            v[i, k] = (v[i, k] + dt * ((fext[i, k] - out[i, k]) * inv_m + gravity[k])) * damp
            x[i, k] += dt * v[i, k]


@njit(cache=True, error_model="numpy")
def commit_forces(x, tets, dm_inv, vol, rots, mu, lam, anp, kappa_node, node_vol, g, decay, gamma, h, sig_prev,
                  keep, take, eps, theta, out):
    """Commit the branches at positions x (rotations ``rots``) and add their excess stress as element
    forces to ``out`` (N,3) N, in two element passes.

    sigma0 is :func:`corotated_stress` at x; then h <- decay h + gamma (sigma0 - sig_prev),
    sig_prev <- sigma0 (``decay``/``gamma`` of the interval since the last commit), and the excess
    stress is ``g (keep h - take sigma0)`` per element (``keep``, ``take`` (T,): 1 and 1 for the stress
    at x_n of an explicit step; exp(-dt/tau) and gamma(dt) for the end-of-step stress of an implicit
    one), added as ``out[a] -= V R excess grad N_a`` (:func:`add_stress_forces`). ``eps`` (T,6) and
    ``theta`` (N,) are work buffers."""
    nt = tets.shape[0]
    if anp:
        theta[:] = 0.0
    for e in range(nt):
        _element_strain(x, tets, dm_inv, rots, e, True, eps)
        if anp:
            q = 0.25 * vol[e] * (eps[e, 0] + eps[e, 1] + eps[e, 2])
            for k in range(4):
                theta[tets[e, k]] += q
    if anp:
        for a in range(theta.shape[0]):
            theta[a] = kappa_node[a] * theta[a] / node_vol[a]
    for e in range(nt):
        m2 = 2.0 * mu[e]
        tr = eps[e, 0] + eps[e, 1] + eps[e, 2]
        if anp:
            iso = 0.25 * (theta[tets[e, 0]] + theta[tets[e, 1]] + theta[tets[e, 2]] + theta[tets[e, 3]]) - m2 * tr / 3.0
        else:
            iso = lam[e] * tr
        s0, s1, s2 = m2 * eps[e, 0] + iso, m2 * eps[e, 1] + iso, m2 * eps[e, 2] + iso
        s3, s4, s5 = m2 * eps[e, 3], m2 * eps[e, 4], m2 * eps[e, 5]
        _branch_element(e, s0, s1, s2, s3, s4, s5, g, decay, gamma, h, sig_prev)
        ge, kh, ks = g[e], keep[e], take[e]
        _scatter_stress(tets, dm_inv, vol, rots, e,
                        -ge * (kh * h[e, 0, 0] - ks * s0), -ge * (kh * h[e, 1, 1] - ks * s1),
                        -ge * (kh * h[e, 2, 2] - ks * s2), -ge * (kh * h[e, 0, 1] - ks * s3),
                        -ge * (kh * h[e, 1, 2] - ks * s4), -ge * (kh * h[e, 2, 0] - ks * s5), out)
