"""Small-strain stiffness of box hexahedra with incompatible bending modes (Wilson, Taylor, Beresford
& Wilson 1973; Taylor, Beresford & Wilson 1976).

An 8-node trilinear hexahedron cannot bend: a pure bending field needs its sides to curve, which
trilinear shapes represent only with a spurious shear strain, so a stiff plate one or two cells
thick (a skin on a soft fat) locks. The nine incompatible modes add ``1 - xi^2``, ``1 - eta^2`` and
``1 - zeta^2`` (natural coordinates) to each displacement component inside the element,

    u = sum_a N_a u_a + sum_k P_k alpha_k,   P = (1 - xi^2, 1 - eta^2, 1 - zeta^2) per component,

with the ``alpha`` (9 per element) condensed out statically, ``K = K_uu - K_ua K_aa^-1 K_au``. On box
elements (edges along the axes, a constant Jacobian) this passes the patch test and represents
pure bending exactly. Full 2 x 2 x 2 Gauss integration; isotropic linear elasticity with Lame
constants from E and nu. Units: m, Pa, N/m.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from surgsim_envs.geometry.box_cells import CORNER_SIGNS

#: (8, 3) natural coordinates of the 2 x 2 x 2 Gauss points, (+-1/sqrt 3)^3; a point's rest position in
#: a box cell is its centre + half its size x these
GAUSS_POINTS = np.stack(np.meshgrid(*([np.array([-1.0, 1.0]) / math.sqrt(3.0)] * 3), indexing="ij"), -1).reshape(-1, 3)


def strain_operator(gradients: np.ndarray) -> np.ndarray:
    """6 x 3n small-strain operator (xx, yy, zz, xy, yz, zx with engineering shears) of n scalar
    fields with ``gradients`` (n, 3), each field carrying three displacement components."""
    n = gradients.shape[0]
    b = np.zeros((6, 3 * n))
    b[0, 0::3], b[1, 1::3], b[2, 2::3] = gradients[:, 0], gradients[:, 1], gradients[:, 2]
    b[3, 0::3], b[3, 1::3] = gradients[:, 1], gradients[:, 0]
    b[4, 1::3], b[4, 2::3] = gradients[:, 2], gradients[:, 1]
    b[5, 0::3], b[5, 2::3] = gradients[:, 2], gradients[:, 0]
    return b


def elasticity_matrix(young: float, poisson: float) -> np.ndarray:
    """6 x 6 isotropic elasticity (Pa) in the order of :func:`strain_operator`."""
    lam = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson))
    mu = young / (2.0 * (1.0 + poisson))
    d = np.diag([2.0 * mu] * 3 + [mu] * 3)
    d[:3, :3] += lam
    return d


def _gauss_parts(size) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per Gauss point of a box with edge lengths ``size``: the strain operators of the nodal shapes
    (8, 6, 24) and of the incompatible modes (8, 6, 9), and the Jacobian determinant (8,)."""
    half = 0.5 * np.asarray(size, dtype=np.float64)
    b_all, ba_all = [], []
    for p in GAUSS_POINTS:
        f = 1.0 + CORNER_SIGNS * p                        # (8, 3) factors of the trilinear shapes
        grad = CORNER_SIGNS * np.stack([f[:, 1] * f[:, 2], f[:, 0] * f[:, 2], f[:, 0] * f[:, 1]], 1) / (8.0 * half)
        b_all.append(strain_operator(grad))
        ba_all.append(strain_operator(np.diag(-2.0 * p / half)))      # gradients of 1 - xi_k^2 (k = 0, 1, 2)
    return np.stack(b_all), np.stack(ba_all), np.full(len(GAUSS_POINTS), float(half.prod()))


def point_parts(size, poisson: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Kuu, Kua, Kaa) of each Gauss point at unit Young's modulus, (8, 24, 24), (8, 24, 9), (8, 9, 9),
    of a box with edge lengths ``size`` (3,) m: the element's parts are their sums weighted by each
    point's Young's modulus."""
    b, ba, det = _gauss_parts(size)
    d = elasticity_matrix(1.0, poisson)
    db, dba = d @ b, d @ ba
    kuu = np.einsum("qki,qkj->qij", b, db) * det[:, None, None]
    kua = np.einsum("qki,qkj->qij", b, dba) * det[:, None, None]
    kaa = np.einsum("qki,qkj->qij", ba, dba) * det[:, None, None]
    return kuu, kua, kaa


def condensed(kuu: np.ndarray, kua: np.ndarray, kaa: np.ndarray) -> np.ndarray:
    """K = Kuu - Kua Kaa^-1 Kau (the incompatible modes condensed out), symmetrised; works on stacks."""
    k = kuu - kua @ np.linalg.solve(kaa, np.swapaxes(kua, -1, -2))
    return 0.5 * (k + np.swapaxes(k, -1, -2))


def box_stiffness(size, young, poisson: float, incompatible: bool = True) -> np.ndarray:
    """24 x 24 stiffness (N/m) of a box hexahedron with edge lengths ``size`` (3,) m, nodes in
    :data:`~surgsim_envs.geometry.box_cells.CORNER_SIGNS` order, dofs (node, axis); with
    ``incompatible`` (default) the nine bending modes condensed in, else the plain trilinear element.
    ``young``: Pa, one value or one per Gauss point ((8,), :data:`GAUSS_POINTS` order: a cell that a
    stiffer inclusion crosses)."""
    e = np.broadcast_to(np.asarray(young, dtype=np.float64), (len(GAUSS_POINTS),))
    kuu, kua, kaa = (np.einsum("q,qij->ij", e, part) for part in point_parts(size, poisson))
    return condensed(kuu, kua, kaa) if incompatible else kuu


class HexAssembly:
    """The global stiffness (3N x 3N, N/m) of box hexahedra ``hexes`` (H, 8) with edge lengths
    ``sizes`` (H, 3) m and Poisson ratios ``poisson`` (H,), for any per-cell Young's modulus:
    the element matrix is computed once per distinct (shape, nu) at unit E, and the sparsity
    pattern with each element entry's place in it once, so :meth:`stiffness` is a scaled sum."""

    def __init__(self, n_nodes: int, hexes: np.ndarray, sizes: np.ndarray, poisson: np.ndarray):
        hexes = np.asarray(hexes, dtype=np.int64)
        sizes = np.asarray(sizes, dtype=np.float64)
        self.poisson = np.array(poisson, dtype=np.float64)
        key = np.concatenate([np.round(sizes / max(float(sizes.max()), 1e-300), 12), self.poisson[:, None]], 1)
        uniq, which = np.unique(key, axis=0, return_inverse=True)
        self.which = which.reshape(-1)
        self._sizes, self._parts = sizes, {}
        self.unit = np.stack([box_stiffness(sizes[np.flatnonzero(self.which == u)[0]], 1.0, float(uniq[u, 3]))
                              for u in range(len(uniq))])
        dofs = (3 * hexes[:, :, None] + np.arange(3)).reshape(len(hexes), 24)
        rows = np.repeat(dofs, 24, axis=1).ravel()
        cols = np.tile(dofs, (1, 24)).ravel()
        n = 3 * n_nodes
        pattern = sp.csr_matrix((np.arange(1, len(rows) + 1, dtype=np.float64), (rows, cols)), shape=(n, n))
        pattern.sum_duplicates()
        self.indptr, self.indices, self.shape = pattern.indptr, pattern.indices, (n, n)
        # the place of every element entry in the pattern's data: its (row, column) found by search
        order = np.lexsort((cols, rows))
        flat = rows[order] * n + cols[order]
        first = np.concatenate([[True], flat[1:] != flat[:-1]])
        self.place = np.empty(len(rows), dtype=np.int64)
        self.place[order] = np.cumsum(first) - 1

    def stiffness(self, young: np.ndarray, point_young: tuple[np.ndarray, np.ndarray] | None = None) -> sp.csr_matrix:
        """K for per-cell ``young`` (H,) Pa; ``point_young`` = (cells (M,), E (M, 8) Pa): those cells'
        Young's modulus per Gauss point instead (cells an inclusion's boundary crosses)."""
        vals = self.unit[self.which] * np.asarray(young, dtype=np.float64)[:, None, None]
        if point_young is not None:
            cells, e = np.asarray(point_young[0], dtype=np.int64), np.asarray(point_young[1], dtype=np.float64)
            for u in np.unique(self.which[cells]):
                sel = self.which[cells] == u
                parts = self._point_parts(int(u))
                kuu, kua, kaa = (np.einsum("mq,qij->mij", e[sel], part) for part in parts)
                vals[cells[sel]] = condensed(kuu, kua, kaa)
        data = np.bincount(self.place, weights=vals.ravel(), minlength=len(self.indices))
        return sp.csr_matrix((data, self.indices.copy(), self.indptr.copy()), shape=self.shape)

    def _point_parts(self, u: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Gauss-point parts (:func:`point_parts`) of distinct (shape, nu) ``u``, computed once."""
        if u not in self._parts:
            i = int(np.flatnonzero(self.which == u)[0])
            self._parts[u] = point_parts(self._sizes[i], float(self.poisson[i]))
        return self._parts[u]


def hex_stiffness(n_nodes: int, hexes: np.ndarray, sizes: np.ndarray, young: np.ndarray,
                  poisson: np.ndarray) -> sp.csr_matrix:
    """Global stiffness (3N x 3N, N/m) of box hexahedra ``hexes`` (H, 8) with edge lengths ``sizes``
    (H, 3) m and per-cell ``young`` (Pa) and ``poisson`` (:class:`HexAssembly`, once)."""
    return HexAssembly(n_nodes, hexes, sizes, poisson).stiffness(young)


__all__ = ["GAUSS_POINTS", "strain_operator", "elasticity_matrix", "point_parts", "condensed", "box_stiffness", "HexAssembly", "hex_stiffness"]
