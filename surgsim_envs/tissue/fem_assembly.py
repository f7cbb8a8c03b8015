"""Linear tetrahedral FEM building blocks: shape gradients, B and D matrices, sparse K assembly.

Notation follows Vandewalle et al. 2003 (section 2.1): Voigt strain ``eps = [exx, eyy, ezz, gxy, gyz, gzx]``
with engineering shear strains, Hooke's law ``sigma = D eps`` (eq. 2), ``eps = B u`` with
``B = [B_0 B_1 B_2 B_3]`` (eq. 3) and element stiffness ``K_e = B^T D B V`` (the paper's
``K^i_mn = B_m^T D^i B_n V^i``). Units: m, Pa, N/m.

Note: the printed B_m in the paper has a typo in the gxy row ("dN/dy, dN/dz, 0"); the row
consistent with gxy = du/dy + dv/dx (and with D's (1-2nu)/2 shear terms) is "dN/dy, dN/dx, 0",
which is what :func:`b_matrices` uses.

The locking-free volumetric part (averaged nodal pressure, ANP) is assembled by
:func:`anp_volumetric_matrix`; see ``docs/models/fem.md``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from surgsim_envs.errors import ConfigError

#: Voigt vector of the identity, m = [1, 1, 1, 0, 0, 0]
VOIGT_M = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])


def shape_gradients(nodes: np.ndarray, tets: np.ndarray):
    """Reference-configuration data of linear tets.

    Returns ``(grads, volumes, dm_inv)``: ``grads`` (T, 4, 3) gradients dN_a/dX (1/m) of the
    four shape functions, ``volumes`` (T,) m^3, and ``dm_inv`` (T, 3, 3) the inverse of the edge
    matrix ``Dm = [X1-X0, X2-X0, X3-X0]`` (so that F = Ds Dm^-1; row j of Dm^-1 is dN_{j+1}/dX).
    Raises ConfigError on degenerate or inverted tets.
    """
    nodes = np.asarray(nodes, dtype=np.float64)
    tets = np.asarray(tets, dtype=np.int64)
    x0 = nodes[tets[:, 0]]
    dm = np.stack([nodes[tets[:, 1]] - x0, nodes[tets[:, 2]] - x0, nodes[tets[:, 3]] - x0], axis=2)
    det = np.linalg.det(dm)
    volumes = det / 6.0
    scale = max(np.ptp(nodes, axis=0).max(), 1e-300) ** 3
    bad = np.flatnonzero(volumes <= 1e-12 * scale)
    if len(bad):
        raise ConfigError(f"{len(bad)} degenerate or inverted tets (first #{bad[0]}, volume {volumes[bad[0]]:.3g} m^3); "
                          "reorder their nodes so the signed volume is positive, or remesh")
    dm_inv = np.linalg.inv(dm)
    grads = np.empty((len(tets), 4, 3))
    grads[:, 1:, :] = dm_inv
    grads[:, 0, :] = -dm_inv.sum(axis=1)
    return grads, volumes, np.ascontiguousarray(dm_inv)


def b_matrices(grads: np.ndarray) -> np.ndarray:
    """Strain-displacement matrices B (T, 6, 12) of Vandewalle et al. 2003 eq. 3 (gxy row corrected, see module doc)."""
    t = len(grads)
    b = np.zeros((t, 6, 12))
    for a in range(4):
        gx, gy, gz = grads[:, a, 0], grads[:, a, 1], grads[:, a, 2]
        c = 3 * a
        b[:, 0, c] = gx
        b[:, 1, c + 1] = gy
        b[:, 2, c + 2] = gz
        b[:, 3, c], b[:, 3, c + 1] = gy, gx          # gxy
        b[:, 4, c + 1], b[:, 4, c + 2] = gz, gy      # gyz
        b[:, 5, c], b[:, 5, c + 2] = gz, gx          # gzx
    return b


def d_matrices(young, poisson) -> np.ndarray:
    """Isotropic Hooke matrices D (T, 6, 6) in Pa (Vandewalle et al. 2003 eq. 2) from per-element E (Pa) and nu."""
    young = np.atleast_1d(np.asarray(young, dtype=np.float64))
    poisson = np.broadcast_to(np.asarray(poisson, dtype=np.float64), young.shape)
    if np.any(young <= 0) or np.any(poisson <= -1.0) or np.any(poisson >= 0.5):
        raise ConfigError("linear FEM needs E > 0 Pa and -1 < nu < 0.5 in every element; "
                          f"got E in [{young.min():.3g}, {young.max():.3g}], nu in [{poisson.min():.3g}, {poisson.max():.3g}]")
    f = young / ((1.0 + poisson) * (1.0 - 2.0 * poisson))
    d = np.zeros((len(young), 6, 6))
    for i in range(3):
        for j in range(3):
            d[:, i, j] = f * (1.0 - poisson) if i == j else f * poisson
        d[:, 3 + i, 3 + i] = f * (1.0 - 2.0 * poisson) / 2.0
    return d


def lame_parameters(young, poisson):
    """(mu, lambda, kappa) in Pa per element: shear modulus, Lame lambda and bulk modulus."""
    young = np.asarray(young, dtype=np.float64)
    poisson = np.asarray(poisson, dtype=np.float64)
    mu = young / (2.0 * (1.0 + poisson))
    lam = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson))
    return mu, lam, lam + 2.0 * mu / 3.0


def deviatoric_d_matrices(young, poisson) -> np.ndarray:
    """D_dev = D - kappa m m^T (T, 6, 6): the shear (volume-preserving) part of Hooke's law."""
    _, _, kappa = lame_parameters(young, poisson)
    return d_matrices(young, poisson) - kappa[:, None, None] * np.outer(VOIGT_M, VOIGT_M)[None]


def element_stiffness(b: np.ndarray, d: np.ndarray, volumes: np.ndarray) -> np.ndarray:
    """K_e = B^T D B V (T, 12, 12) in N/m; DOF order (node0 x,y,z, node1 x,y,z, ...)."""
    return np.einsum("tki,tkl,tlj,t->tij", b, d, b, volumes, optimize=True)


def rotate_element_matrices(ke: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """Warped stiffness R K_e R^T with R = blockdiag(R_e x4), for per-element rotations (T, 3, 3)."""
    k = ke.reshape(-1, 4, 3, 4, 3)
    out = np.einsum("tik,takbl,tjl->taibj", rotations, k, rotations, optimize=True)
    return out.reshape(-1, 12, 12)


def element_dofs(tets: np.ndarray) -> np.ndarray:
    """(T, 12) global DOF indices of each element."""
    tets = np.asarray(tets, dtype=np.int64)
    return (3 * tets[:, :, None] + np.arange(3)[None, None, :]).reshape(-1, 12)


def assemble(tets: np.ndarray, ke: np.ndarray, n_nodes: int) -> sp.csr_matrix:
    """Global sparse (3N, 3N) matrix from element matrices (T, 12, 12)."""
    dofs = element_dofs(tets)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    k = sp.coo_matrix((ke.ravel(), (rows, cols)), shape=(3 * n_nodes, 3 * n_nodes)).tocsr()
    k.sum_duplicates()
    return k


def nodal_volumes(tets: np.ndarray, volumes: np.ndarray, n_nodes: int) -> np.ndarray:
    """V_a = sum over incident tets of V_e / 4 (m^3): the node's share of the volume."""
    out = np.zeros(n_nodes)
    np.add.at(out, np.asarray(tets).ravel(), np.repeat(volumes / 4.0, 4))
    return out


def nodal_average(tets: np.ndarray, volumes: np.ndarray, values: np.ndarray, n_nodes: int) -> np.ndarray:
    """Volume-weighted nodal average of a per-element quantity."""
    acc = np.zeros(n_nodes)
    np.add.at(acc, np.asarray(tets).ravel(), np.repeat(values * volumes / 4.0, 4))
    return acc / nodal_volumes(tets, volumes, n_nodes)


def anp_volumetric_matrix(tets, grads, volumes, kappa_node, n_nodes, rotations=None) -> sp.csr_matrix:
    """Volumetric stiffness of the averaged-nodal-pressure (ANP) formulation (Bonet & Burton 1998).

    The volume change theta_e = div u of each tet is averaged to the nodes,
    ``theta_a = sum_e (V_e/4) theta_e / V_a``, and the volumetric energy is
    ``sum_a kappa_a V_a theta_a^2 / 2``.  Its stiffness is ``Bv^T diag(kappa_a V_a) Bv`` with
    rows ``b_a = d theta_a / d u``. ``rotations`` (T,3,3) warps it for the corotational model
    (d theta_e / d x_n = R_e grad N_n).
    """
    vnode = nodal_volumes(tets, volumes, n_nodes)
    bv = anp_volume_operator(tets, grads, volumes, n_nodes, rotations)
    return (bv.T @ sp.diags(kappa_node * vnode) @ bv).tocsr()


def anp_volume_operator(tets, grads, volumes, n_nodes, rotations=None) -> sp.csr_matrix:
    """Bv (N, 3N): averaged nodal volume change ``theta = Bv u`` (dimensionless) of a nodal
    displacement u (m), rows ``b_a = d theta_a / du`` with ``theta_a = sum_e (V_e/4) div_e u / V_a``;
    ``rotations`` (T,3,3) warps it (d theta_e / d x_n = R_e grad N_n)."""
    tets = np.asarray(tets, dtype=np.int64)
    vnode = nodal_volumes(tets, volumes, n_nodes)
    g = grads if rotations is None else np.einsum("tij,tnj->tni", rotations, grads)
    # entry (a, 3n+i) += V_e/(4 V_a) g[e, n, i] for every a in e, n in e
    a_idx = np.repeat(tets, 12, axis=1)                              # (T, 4*12): a repeated per (n,i)
    col = np.tile(element_dofs(tets), (1, 4))                        # (T, 4*12)
    w = (volumes[:, None] / 4.0) / vnode[tets]                       # (T, 4) weight per a
    val = w[:, :, None] * g.reshape(-1, 1, 12)                       # (T, 4, 12)
    return sp.coo_matrix((val.ravel(), (a_idx.ravel(), col.ravel())), shape=(n_nodes, 3 * n_nodes)).tocsr()


def barycentric_locate(nodes: np.ndarray, tets: np.ndarray, points: np.ndarray, tol: float = 1e-9):
    """Containing tet and barycentric weights of each point (P, 3) in the mesh (nodes, tets).

    Returns ``(tet_index (P,), weights (P, 4))``. Points outside the mesh get the tet with the
    least negative weight (clamped extrapolation), so callers can still interpolate near faces.
    """
    nodes = np.asarray(nodes, dtype=np.float64)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    _, _, dm_inv = shape_gradients(nodes, tets)
    x0 = nodes[np.asarray(tets)[:, 0]]
    best = np.full(len(points), -1, dtype=np.int64)
    best_w = np.zeros((len(points), 4))
    best_min = np.full(len(points), -np.inf)
    chunk = max(1, 2_000_000 // max(len(tets), 1))
    for s in range(0, len(points), chunk):
        p = points[s:s + chunk]
        lam = np.einsum("tij,ptj->pti", dm_inv, p[:, None, :] - x0[None])   # (P, T, 3)
        w = np.concatenate([1.0 - lam.sum(axis=2, keepdims=True), lam], axis=2)
        mins = w.min(axis=2)
        k = np.argmax(mins, axis=1)
        best[s:s + chunk] = k
        best_w[s:s + chunk] = w[np.arange(len(p)), k]
        best_min[s:s + chunk] = mins[np.arange(len(p)), k]
    return best, best_w


def interpolate(values: np.ndarray, tets: np.ndarray, tet_index: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Barycentric interpolation of nodal ``values`` (N, k) at located points."""
    corners = np.asarray(tets)[tet_index]                    # (P, 4)
    return np.einsum("pa,pak->pk", weights, values[corners])
