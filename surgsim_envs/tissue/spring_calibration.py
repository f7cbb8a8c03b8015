"""Spring constants identified from the continuum: a mass-spring network that matches linear FEM.

A plain spring network on tet edges cannot represent an isotropic solid: its small-strain
stiffness obeys the Cauchy relations (lambda = mu), and on the Kuhn box lattice the edges have
only one diagonal per face, so the network is anisotropic (shear-normal coupling) and 36-53 %
too soft in sphere indentation. This module identifies spring constants per spring and a volume
term per node so that the network's small-strain energy matches linear elasticity (E, nu) of
every tet:

1. **Layout.** Springs on the tet edges plus one *cross-face* spring per interior face, joining
   the two vertices opposite that face (the "across" springs of cloth/cubical mass-spring
   models). On the Kuhn lattice these add the missing face diagonals (1,-1,0), ... so the spring
   directions include the 3 axes and all 6 face diagonals; such a set can carry the fully
   symmetric isotropic tensor exactly (axis springs half the diagonals: Kot et al. 2015; San
   Vicente et al. 2009 cubical mass-spring model).
2. **Split.** Isotropic elasticity is C = mu T + (lambda - mu) I (x) I with T_ijkl =
   d_ij d_kl + d_ik d_jl + d_il d_jk the fully symmetric isotropic tensor. Central springs can
   only make fully symmetric tensors, so they get ``mu T`` and a volume term gets the rest,
   ``k_v = lambda - mu`` (Pa; >= 0 for nu >= 1/4; for nu < 1/4 the springs take the whole C in
   the least-squares sense and k_v = 0).
3. **Fit (virial matching, per node).** Under a uniform strain eps a spring of rest length L
   and direction d stores 0.5 k L^2 (d.eps.d)^2; half of it is attributed to each end node. For
   every node i the springs' summed (Mandel 6x6) stiffness must equal that of its share of the
   continuum, sum over its tets of w_ti V_t (mu_t T + ...), w_ti the tet's solid angle at i over
   the sum of its four (:func:`corner_shares`; V_t/4 made boundary nodes of lattices inconsistent
   with the springs' half-per-end split): 21 equations per node, one unknown per
   spring, k >= 0. Solved as one sparse non-negative least-squares problem (projected
   Barzilai-Borwein gradient). It is the nodal version of per-element stiffness fitting (Lloyd,
   Szekely, Harders 2007, "Identification of spring parameters for deformable object simulation",
   IEEE TVCG 13(5)), which cannot succeed per tet because a tet's six edges lack directions; the
   per-node patch has them. Summed over nodes, the network's energy under any uniform strain is
   that of the FEM mesh wherever the fit is exact (a patch test); the relative residual is
   reported (``Calibration.residual``): ~1 % inside a uniform lattice, more on the surface and in
   strongly stretched cells (aspect > ~1.7, where no non-negative set of these directions is
   isotropic).
4. **Volume term at the nodes** (averaged nodal volume, Bonet & Burton 1998, as ``fem``'s ANP):
   E = 0.5 sum_i k_v,i (V_i - V_i0)^2 / V_i0 with V_i = sum over the node's tets of V_t / 4 and
   k_v,i the volume-weighted mean of its tets' lambda - mu, plus the bulk part of whatever the
   springs could not fit at that node (:func:`bulk_completion`). A per-tet volume term locks linear tets
   as nu -> 0.5 (the indentation force grows 25 % too stiff at nu = 0.49); the nodal one does not.

Units: m, Pa, N/m. numpy + scipy only (the stepping kernels are in
:mod:`surgsim_envs.tissue.nodal_volume_kernels`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from surgsim_envs.errors import ConfigError

#: the four faces of a tet, each listed by the local vertices it contains (face q is opposite vertex q)
TET_FACES = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
_SQRT2 = math.sqrt(2.0)
_IU = np.triu_indices(6)
#: weights that make the 21 upper-triangle entries of a symmetric 6x6 a Frobenius-norm vector
_WU = np.where(_IU[0] == _IU[1], 1.0, _SQRT2)
_M = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
#: iteration cap and relative projected-gradient tolerance of the non-negative least-squares fit
FIT_MAX_ITER = 3000
FIT_TOL = 1e-9
#: springs the fit leaves below this fraction of the median live constant are dropped and the rest refitted
#: (:func:`calibration_basis`): ~7 % fewer springs to step on the palpation slab, fit residual 0.031 -> 0.032
PRUNE_FRACTION = 0.1


@dataclass(frozen=True)
class Calibration:
    """Result of :func:`calibrate`.

    pairs: (S,2) node indices of the springs (edges, then cross-face springs), i < j.
    stiffness: (S,) spring constants k (N/m), >= 0.
    node_bulk: (N,) volume-term stiffness k_v,i (Pa) of each node's averaged volume.
    residual: relative Frobenius misfit of the nodal stiffness tensors (0 = exact patch test).
    iterations: iterations of the non-negative least-squares solver.
    n_edges: the first ``n_edges`` pairs are tet edges, the rest cross-face springs.
    """

    pairs: np.ndarray
    stiffness: np.ndarray
    node_bulk: np.ndarray
    residual: float
    iterations: int
    n_edges: int


def corner_shares(X: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """(T,4) fraction of each tet's volume owned by each of its corners, proportional to the solid
    angle the tet subtends there (Van Oosterom & Strackee 1983, tan(omega/2) = |a.(b x c)| /
    (abc + (a.b)c + (a.c)b + (b.c)a)).

    On a cube lattice split into tets (Kuhn) the six tets are congruent and the solid angles at a
    cube corner add up to an octant, so every corner owns 1/8 of each cube around it, as the springs'
    half-per-end energy does (on stretched boxes approximately: 0.88-1.15 x 1/8 at 3:2:1).
    The usual V_t/4 lumping gives the corners of a Kuhn box 1/4 (the two ends of the split
    diagonal, in all 6 tets) or 1/12 (the others, in 2): averaged out inside, but on boundary edges,
    corners and symmetry cuts the fit then pulls the springs there soft (the axis node of the
    quarter indentation slab was 1.4x too compliant)."""
    omega = np.empty((len(tets), 4))
    for a in range(4):
        r = [X[tets[:, b]] - X[tets[:, a]] for b in range(4) if b != a]
        ln = [np.linalg.norm(v, axis=1) for v in r]
        num = np.abs(np.einsum("ij,ij->i", r[0], np.cross(r[1], r[2])))
        den = (ln[0] * ln[1] * ln[2] + np.einsum("ij,ij->i", r[0], r[1]) * ln[2]
               + np.einsum("ij,ij->i", r[0], r[2]) * ln[1] + np.einsum("ij,ij->i", r[1], r[2]) * ln[0])
        omega[:, a] = 2.0 * np.arctan2(num, den)
    return omega / omega.sum(axis=1, keepdims=True)


def cross_face_pairs(tets: np.ndarray, n_nodes: int) -> np.ndarray:
    """(F,2) sorted node pairs opposite each interior face (the two tets sharing it), unique."""
    pairs, _ = cross_face_tets(tets, n_nodes)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    return np.unique(pairs, axis=0) if len(pairs) else np.zeros((0, 2), dtype=np.int64)


def cross_face_tets(tets: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """For every interior face: the sorted node pair opposite it (F,2) and the two tets sharing it (F,2)
    (not unique: two faces may give one pair)."""
    tets = np.asarray(tets, dtype=np.int64)
    faces = np.sort(tets[:, TET_FACES], axis=2).reshape(-1, 3)
    opposite = tets.reshape(-1)
    key = (faces[:, 0] * n_nodes + faces[:, 1]) * n_nodes + faces[:, 2]
    order = np.argsort(key, kind="stable")
    ks = key[order]
    shared = np.flatnonzero(ks[1:] == ks[:-1])
    a, b = order[shared], order[shared + 1]
    pairs = np.sort(np.stack([opposite[a], opposite[b]], axis=1), axis=1)
    return pairs, np.stack([a // 4, b // 4], axis=1)


def spring_layout(volume) -> tuple[np.ndarray, int]:
    """(pairs (S,2), n_edges): the tet edges, then cross-face springs that are not edges."""
    n = volume.n_nodes
    edges = np.asarray(volume.edges(), dtype=np.int64)
    cross = cross_face_pairs(volume.tets, n)
    if len(cross):
        is_edge = np.isin(cross[:, 0] * n + cross[:, 1], edges[:, 0] * n + edges[:, 1])
        cross = cross[~is_edge]
    return np.concatenate([edges, cross]), len(edges)


def _mandel_dyad(d: np.ndarray) -> np.ndarray:
    """(S,6) Mandel vector of d (x) d for unit directions d (S,3): spring strain = w . eps."""
    return np.stack([d[:, 0] ** 2, d[:, 1] ** 2, d[:, 2] ** 2, _SQRT2 * d[:, 1] * d[:, 2],
                     _SQRT2 * d[:, 0] * d[:, 2], _SQRT2 * d[:, 0] * d[:, 1]], axis=1)


def _nnls(A: sp.csr_matrix, b: np.ndarray, max_iter: int = FIT_MAX_ITER, tol: float = FIT_TOL, x0=None):
    """min 0.5 |A x - b|^2 subject to x >= 0 (projected Barzilai-Borwein gradient from ``x0``, default 0).
    Returns (x, iterations)."""
    # plain numpy reductions, not BLAS dot: a multi-threaded BLAS stalls on a loaded machine
    def dot(u, v):
        return float(np.sum(u * v))

    at = A.T.tocsr()
    x = np.zeros(A.shape[1]) if x0 is None else np.maximum(np.asarray(x0, dtype=np.float64), 0.0)
    g = at @ (A @ x - b)
    g0 = at @ b                        # the gradient at x = 0 sets the tolerance, whatever the start
    scale = math.sqrt(dot(g0, g0)) + 1e-300
    step = 1.0 / max(float(sp.linalg.norm(A, "fro")) ** 2 / max(A.shape[1], 1), 1e-300)
    it = 0
    for it in range(1, max_iter + 1):
        xn = np.maximum(x - step * g, 0.0)
        gn = at @ (A @ xn - b)
        s, y = xn - x, gn - g
        sy = dot(s, y)
        if sy > 0:
            step = dot(s, s) / sy
        x, g = xn, gn
        projected = np.where(x > 0, g, np.minimum(g, 0.0))
        if math.sqrt(dot(projected, projected)) <= tol * scale:
            break
    return x, it


def _norm(v: np.ndarray) -> float:
    """Euclidean norm by a plain reduction (a multi-threaded BLAS dot stalls ~30 ms on a loaded machine)."""
    return math.sqrt(float(np.sum(v * v)))


def _check_material(E: np.ndarray, nu: np.ndarray) -> None:
    if np.any(~np.isfinite(E)) or np.any(E <= 0) or np.any(nu <= -1.0) or np.any(nu >= 0.5):
        raise ConfigError("spring calibration needs E > 0 Pa and -1 < nu < 0.5 in every tet "
                          f"(got E in [{E.min():.3g}, {E.max():.3g}], nu in [{nu.min():.3g}, {nu.max():.3g}])")


def _lame(E: np.ndarray, nu: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mu, lambda, k_v = max(lambda - mu, 0)) per tet (Pa)."""
    mu = E / (2.0 * (1.0 + nu))
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    return mu, lam, np.maximum(lam - mu, 0.0)


def _node_target_matrices(volume) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """(B_eye, B_mm), each (21 N, T): the nodal targets (Mandel 6x6 upper triangles, Frobenius-weighted)
    are ``B_eye @ (2 mu) + B_mm @ (lambda - k_v)``; tet t adds its corner share (solid angle) of
    V_t (I or m m^T) to each of its four nodes."""
    tets = np.asarray(volume.tets, dtype=np.int64)
    nt, n = len(tets), volume.n_nodes
    share = (volume.tet_volumes()[:, None] * corner_shares(volume.nodes, tets)).ravel()      # (4T,)
    rows = (tets.reshape(-1)[:, None] * 21 + np.arange(21)[None]).ravel()
    cols = np.repeat(np.repeat(np.arange(nt), 4), 21)
    eye_u = (_IU[0] == _IU[1]).astype(float) * _WU
    mm_u = np.outer(_M, _M)[_IU] * _WU
    out = []
    for form in (eye_u, mm_u):
        vals = (share[:, None] * form[None]).ravel()
        out.append(sp.csr_matrix((vals, (rows, cols)), shape=(21 * n, nt)))
    return out[0], out[1]


def _spring_matrix(volume, pairs: np.ndarray) -> sp.csr_matrix:
    """(21 N, S): half of each spring's small-strain stiffness 0.5 k L^2 (w w^T) at each end node per unit k."""
    X, n = volume.nodes, volume.n_nodes
    d = X[pairs[:, 1]] - X[pairs[:, 0]]
    length = np.linalg.norm(d, axis=1)
    if np.any(length <= 0):
        raise ConfigError(f"volume '{volume.name}' has coincident nodes; merge them before calibrating springs")
    w = _mandel_dyad(d / length[:, None])
    q = (0.5 * length ** 2)[:, None] * (w[:, _IU[0]] * w[:, _IU[1]]) * _WU[None]   # (S,21), per end node
    ns = len(pairs)
    rows = (np.concatenate([pairs[:, 0], pairs[:, 1]])[:, None] * 21 + np.arange(21)[None]).ravel()
    cols = np.repeat(np.concatenate([np.arange(ns), np.arange(ns)]), 21)
    return sp.csr_matrix((np.concatenate([q, q]).ravel(), (rows, cols)), shape=(21 * n, ns))


def _fit(A: sp.csr_matrix, b: np.ndarray, initial=None) -> tuple[np.ndarray, int]:
    """Non-negative spring constants (S,) minimising |A k - b| (column-scaled projected BB)."""
    colnorm = np.sqrt(np.asarray(A.multiply(A).sum(axis=0)).ravel())
    colnorm[colnorm == 0] = 1.0
    x0 = None
    if initial is not None and np.shape(initial) == (A.shape[1],):
        x0 = np.asarray(initial, dtype=np.float64) * colnorm
    x, iters = _nnls((A @ sp.diags(1.0 / colnorm)).tocsr(), b, x0=x0)
    return x / colnorm, iters


def _spring_tet_weights(volume, pairs: np.ndarray, n_edges: int) -> sp.csr_matrix:
    """(S, T) share of tet t in spring s: V_t over the summed volume of the tets the spring spans (the
    tets around an edge; the two tets sharing the face of a cross-face spring); rows sum to 1."""
    tets = np.asarray(volume.tets, dtype=np.int64)
    n, nt = volume.n_nodes, len(tets)
    key = pairs[:, 0] * n + pairs[:, 1]
    order = np.argsort(key, kind="stable")
    te = np.sort(np.stack([tets[:, [0, 0, 0, 1, 1, 2]].ravel(), tets[:, [1, 2, 3, 2, 3, 3]].ravel()], axis=1), axis=1)
    edge_rows = order[np.searchsorted(key[order], te[:, 0] * n + te[:, 1])]
    edge_tets = np.repeat(np.arange(nt), 6)
    cpairs, ctets = cross_face_tets(tets, n)
    ckey = cpairs[:, 0] * n + cpairs[:, 1]
    pos = np.searchsorted(key[order], ckey)
    hit = (pos < len(key)) & (key[order][np.minimum(pos, len(key) - 1)] == ckey)
    crow = order[np.minimum(pos, len(key) - 1)]
    keep = hit & (crow >= n_edges)           # cross pairs that are edges are edges (weighted above)
    rows = np.concatenate([edge_rows, np.repeat(crow[keep], 2)])
    cols = np.concatenate([edge_tets, ctets[keep].ravel()])
    vol = volume.tet_volumes()
    W = sp.csr_matrix((vol[cols], (rows, cols)), shape=(len(pairs), nt))   # duplicates add up
    total = np.asarray(W.sum(axis=1)).ravel()
    return (sp.diags(1.0 / np.where(total > 0, total, 1.0)) @ W).tocsr()


@dataclass(frozen=True)
class CalibrationBasis:
    """The calibration as a linear map of the tets' shear moduli (all nu >= 1/4), built once per mesh.

    The springs' target mu T is linear in mu, so the constants of a uniform field are mu x ``unit``
    (the fit at mu = 1 Pa). For a field, each spring takes the V-weighted mean shear modulus of the
    tets it spans: k = ``weights`` @ mu, weights[s, t] = unit_s V_t / sum of V over the spring's tets
    (the same rule that maps E to springs in ``mass_spring``); the volume term k_v,i is the
    V-weighted mean of the node's tets' lambda - mu plus the bulk completion of the remaining misfit
    (linear in the moduli up to its clamp at 0). A new material is then a few sparse products
    (``calibration``), not a fit: ``scale_material`` between episodes costs ~ms.
    """

    pairs: np.ndarray
    n_edges: int
    unit: np.ndarray
    weights: sp.csr_matrix
    springs: sp.csr_matrix
    target_eye: sp.csr_matrix
    target_mm: sp.csr_matrix
    node_bulk_weights: sp.csr_matrix
    node_volume: np.ndarray
    iterations: int

    def calibration(self, young, poisson) -> Calibration:
        """:class:`Calibration` of the per-tet field (E (T,) Pa, nu (T,), every nu >= 1/4)."""
        nt = self.weights.shape[1]
        E = np.broadcast_to(np.asarray(young, dtype=np.float64), (nt,))
        nu = np.broadcast_to(np.asarray(poisson, dtype=np.float64), (nt,))
        _check_material(E, nu)
        if np.any(nu < 0.25):
            raise ConfigError(f"CalibrationBasis needs nu >= 1/4 in every tet (got min {nu.min():.3g}); "
                              "use calibrate(), which fits such fields directly")
        mu, lam, kv = _lame(E, nu)
        k = self.weights @ mu
        b = self.target_eye @ (2.0 * mu) + self.target_mm @ (lam - kv)
        misfit = self.springs @ k - b
        residual = _norm(misfit) / (_norm(b) + 1e-300)
        bulk = self.node_bulk_weights @ kv + bulk_completion(misfit, len(self.node_volume)) / self.node_volume
        return Calibration(self.pairs, k, bulk, residual, 0, self.n_edges)


def calibration_basis(volume) -> CalibrationBasis:
    """Fit the springs of ``volume`` once at mu = 1 Pa (nu >= 1/4) and return the linear map of
    :class:`CalibrationBasis` (the one non-negative least-squares solve per mesh)."""
    tets = np.asarray(volume.tets, dtype=np.int64)
    n, nt = volume.n_nodes, len(tets)
    pairs, n_edges = spring_layout(volume)
    A = _spring_matrix(volume, pairs)
    B_eye, B_mm = _node_target_matrices(volume)
    b = B_eye @ np.full(nt, 2.0) + B_mm @ np.ones(nt)
    unit, iters = _fit(A, b)
    live = unit > 0
    small = live & (unit < PRUNE_FRACTION * np.median(unit[live])) if live.any() else live
    if small.any():            # near-zero springs cost a kernel visit each and carry almost nothing
        keep = live & ~small
        refit, more = _fit(A[:, keep].tocsr(), b, initial=unit[keep])
        unit = np.zeros_like(unit)
        unit[keep] = refit
        iters += more
    W = (sp.diags(unit) @ _spring_tet_weights(volume, pairs, n_edges)).tocsr()
    quarter = np.repeat(volume.tet_volumes() / 4.0, 4)     # the volume term's own nodal volumes (V_t / 4)
    Q = sp.csr_matrix((quarter, (tets.reshape(-1), np.repeat(np.arange(nt), 4))), shape=(n, nt))
    node_vol = np.asarray(Q.sum(axis=1)).ravel()
    return CalibrationBasis(pairs, int(n_edges), unit, W, A, B_eye, B_mm,
                            (sp.diags(1.0 / node_vol) @ Q).tocsr(), node_vol, int(iters))


def calibrate(volume, young, poisson, initial=None, basis: CalibrationBasis | None = None) -> Calibration:
    """Spring constants and nodal volume stiffness matching linear elasticity of every tet.

    volume: the tet :class:`~surgsim_envs.geometry.Volume` (m); young (T,) Pa, poisson (T,) per tet.
    With nu >= 1/4 everywhere (k_v >= 0: the springs carry mu T) the result is linear in the moduli:
    :class:`CalibrationBasis` (``basis``, built here if not given). With some nu < 1/4 the springs
    must fit lambda != mu in the least-squares sense, a non-negative fit of the field itself
    (``initial``: optional (S,) spring constants, N/m, to start it from).
    See the module docstring for the method.
    """
    tets = np.asarray(volume.tets, dtype=np.int64)
    nt = len(tets)
    E = np.broadcast_to(np.asarray(young, dtype=np.float64), (nt,))
    nu = np.broadcast_to(np.asarray(poisson, dtype=np.float64), (nt,))
    _check_material(E, nu)
    if np.all(nu >= 0.25):
        return (basis if basis is not None else calibration_basis(volume)).calibration(E, nu)
    n = volume.n_nodes
    mu, lam, kv = _lame(E, nu)
    pairs, n_edges = spring_layout(volume)
    A = _spring_matrix(volume, pairs)
    B_eye, B_mm = _node_target_matrices(volume)
    b = B_eye @ (2.0 * mu) + B_mm @ (lam - kv)
    k, iters = _fit(A, b, initial)
    misfit = A @ k - b
    residual = float(np.linalg.norm(misfit) / (np.linalg.norm(b) + 1e-300))
    quarter = np.repeat(volume.tet_volumes() / 4.0, 4)
    node_vol = np.bincount(tets.reshape(-1), weights=quarter, minlength=n)
    node_bulk = np.bincount(tets.reshape(-1), weights=quarter * np.repeat(kv, 4), minlength=n) / node_vol
    node_bulk = node_bulk + bulk_completion(misfit, n) / node_vol
    return Calibration(pairs, k, node_bulk, residual, int(iters), int(n_edges))


def bulk_completion(misfit: np.ndarray, n: int) -> np.ndarray:
    """(N,) bulk stiffness (Pa m^3) the volume term adds where the springs miss some: the least-squares
    projection of each node's deficit (target - springs, Mandel 6x6) on the volume term's form m m^T,
    (m^T R_i m) / 9, kept where positive. ``misfit`` is the fit's (21 N,) residual springs - target."""
    r = -np.asarray(misfit).reshape(n, 21) / _WU[None]
    full = np.zeros((n, 6, 6))
    full[:, _IU[0], _IU[1]] = r
    full[:, _IU[1], _IU[0]] = r
    return np.maximum(np.einsum("i,nij,j->n", _M, full, _M) / 9.0, 0.0)
