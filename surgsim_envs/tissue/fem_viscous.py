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
