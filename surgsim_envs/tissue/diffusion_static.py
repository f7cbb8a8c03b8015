"""Equilibria of the diffusion model (Zhong et al. 2016): the steady concentration under a constant load,
the static positions (``static_solve``) and the contact compliance used by indentation
benchmarks. Functions of a built :class:`~surgsim_envs.tissue.diffusion.DiffusionModel` (its
operators and coefficients); scipy sparse solves, no state is changed.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.errors import ConfigError


def steady_matrix(model):
    """Sparse (N,N) 1/s matrix M with dC/dt = -M C + p/tau."""
    from scipy.sparse import csr_matrix, identity

    n = model.n_nodes_total
    ptr, idx, val = model._rates
    A = csr_matrix((val, idx, ptr), shape=(n, n))
    diag = csr_matrix((np.asarray(A.sum(axis=1)).ravel(), (np.arange(n), np.arange(n))), shape=(n, n))
    return (identity(n, format="csr") * (1.0 / model.load_time) + diag - A).tocsr()


def node_gradients(model, conc: np.ndarray) -> np.ndarray:
    """(N,3) Pa/m gradient of ``conc`` (N,) or (N,K) -> (N,K,3) at every node (eqs. 9.15/9.20/9.21)."""
    ptr, idx, val = model._grad
    n = model.n_nodes_total
    rows = np.repeat(np.arange(n), np.diff(ptr))
    c = conc[idx]
    if c.ndim == 1:
        g = np.zeros((n, 3))
        np.add.at(g, rows, val * c[:, None])
    else:
        g = np.zeros((n, c.shape[1], 3))
        np.add.at(g, rows, val[:, None, :] * c[:, :, None])
    return g


def steady_concentration(model, f: np.ndarray) -> np.ndarray:
    """(N,) Pa, the concentration a constant force ``f`` (N,3) N settles to: the sparse solve of
    ``sum_j a_ij (C_j - C_i) + (p_i - C_i)/tau = 0`` over the surface nodes."""
    from scipy.sparse.linalg import spsolve

    act = model._active_nodes
    p = np.zeros(model.n_nodes_total)
    gn = np.einsum("ij,ij->i", f, model._normals)
    p[act] = np.where(gn[act] < 0, -gn[act] / model._areas[act], 0.0)
    c = np.zeros(model.n_nodes_total)
    c[act] = spsolve(steady_matrix(model)[act][:, act].tocsc(), p[act] / model.load_time)
    return c


def static_positions(model, f: np.ndarray) -> np.ndarray:
    """(N,3) m equilibrium positions under a constant force ``f``: the steady concentration, then
    per free node the bulk displacement that balances the diffused load, the gradient force, the
    direct part of the external force and gravity (a cubic in |u| when nonlinear > 0, Newton)."""
    c = steady_concentration(model, f)
    g = node_gradients(model, c)
    gn = np.einsum("ij,ij->i", f, model._normals)
    direct = f - np.minimum(gn, 0.0)[:, None] * model._normals
    total = (-(model._areas * c)[:, None] * model._normals + direct - np.einsum("nij,nj->ni", model._wgrad, g)
             + model.masses[:, None] * model.gravity[None, :])
    out = model.rest_positions.copy()
    free = model._free
    mag = np.linalg.norm(total[free], axis=1)
    k0 = model._areas[free] * model._kappa[free]
    beta = model._beta[free]
    u = mag / k0
    for _ in range(60):                       # Newton on k0 (u + beta u^3) = |f|
        r = k0 * (u + beta * u ** 3) - mag
        u = np.maximum(u - r / (k0 * (1.0 + 3.0 * beta * u * u)), 0.0)
    unit = total[free] / np.where(mag > 0, mag, 1.0)[:, None]
    out[free] += u[:, None] * unit
    out[model.fixed] = model.fixed_targets[model.fixed]
    return out


def contact_compliance(model, nodes, axis: int = 2) -> np.ndarray:
    """(k,k) m/N: displacement of ``nodes`` along ``axis`` per unit force along ``axis`` at each of
    them, the force pressing into the surface (the static response is linear there when
    nonlinear = 0; benchmarks use it for frictionless indentation, bench/material.indent)."""
    from scipy.sparse.linalg import splu

    nodes = np.asarray(nodes, dtype=np.int64).reshape(-1)
    n = model.n_nodes_total
    act = model._active_nodes
    pos_in_act = -np.ones(n, dtype=np.int64)
    pos_in_act[act] = np.arange(len(act))
    if np.any(pos_in_act[nodes] < 0):
        raise ConfigError("contact_compliance: every node must be a surface node")
    e = np.zeros(3)
    e[axis] = 1.0
    sign = -np.sign(model._normals[nodes] @ e)            # unit force pressing into the surface
    sign[sign == 0] = -1.0
    lu = splu(steady_matrix(model)[act][:, act].tocsc())
    P = np.zeros((len(act), len(nodes)))                  # pressure per unit force, times 1/tau
    for col, (i, sg) in enumerate(zip(nodes, sign)):
        fn = sg * float(model._normals[i] @ e)
        P[pos_in_act[i], col] = max(-fn, 0.0) / model._areas[i] / model.load_time
    C = np.zeros((n, len(nodes)))
    C[act] = lu.solve(P)
    g = node_gradients(model, C)
    load = -(model._areas[:, None, None] * C[:, :, None]) * model._normals[:, None, :] \
        - np.einsum("nij,nkj->nki", model._wgrad, g)
    for col, (i, sg) in enumerate(zip(nodes, sign)):    # the direct (tangential) part at its own node
        fvec = sg * e
        fn = float(fvec @ model._normals[i])
        load[i, col] += fvec - min(fn, 0.0) * model._normals[i]
    k0 = np.where(model._areas * model._kappa > 0, model._areas * model._kappa, np.inf)
    u = load[nodes, :, axis] / k0[nodes, None]
    u[model.fixed[nodes]] = 0.0
    return u * sign[None, :]                               # per unit force along +axis
