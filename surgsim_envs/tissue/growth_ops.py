"""Linear element operators of the growth iteration (Vandewalle et al. 2003, eqs. 2-7): strain, stress, loads.

Per tet e (linear 4-node, constant strain): Voigt strain ``eps_e = B_e u`` (engineering shears,
order xx, yy, zz, xy, yz, zx; paper eq. 3), Voigt stress ``sigma_e = S(eps)_e`` and nodal
forces ``f = sum_e V_e B_e^T sigma_e``. The stress operator ``S`` is the one whose stiffness is
the model's ``stiffness_matrix`` (so ``K u = f(S(B u))`` exactly, tested):

* ``formulation="standard"``: Hooke's law per tet, ``sigma_e = D_e eps_e`` (paper eq. 2);
* ``formulation="anp"``: averaged nodal pressure, ``sigma_e = D_dev,e eps_e + m pbar_e`` with
  ``pbar_e`` the mean over the tet's nodes of ``p_a = kappa_a theta_a``,
  ``theta_a = sum_{e in a} (V_e/4) tr(eps_e) / V_a`` (docs/models/fem.md).

An eigenstrain (growth strain) ``eps_G`` enters as ``sigma = S(B u - eps_G)`` and as the load
``R = f(S(eps_G))``: the paper's ``R = int B^T D alpha sigma_growth dV`` (eq. 4) is this load for
``eps_G = alpha sigma_growth`` (tensor components). All arrays are float64; units m, Pa, N.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from surgsim_envs.tissue import fem_assembly as asm

#: Voigt stress -> tensor-strain-consistent Voigt strain: engineering shear = 2 x tensor shear
VOIGT_ENGINEERING = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])


def voigt_to_tensor(v: np.ndarray) -> np.ndarray:
    """(T,6) Voigt stress (xx, yy, zz, xy, yz, zx) -> (T,3,3) symmetric tensors."""
    t = np.empty((len(v), 3, 3))
    t[:, 0, 0], t[:, 1, 1], t[:, 2, 2] = v[:, 0], v[:, 1], v[:, 2]
    t[:, 0, 1] = t[:, 1, 0] = v[:, 3]
    t[:, 1, 2] = t[:, 2, 1] = v[:, 4]
    t[:, 2, 0] = t[:, 0, 2] = v[:, 5]
    return t


def tensor_to_voigt(t: np.ndarray) -> np.ndarray:
    """(T,3,3) symmetric tensors -> (T,6) Voigt (tensor components, no factor 2 on shears)."""
    return np.stack([t[:, 0, 0], t[:, 1, 1], t[:, 2, 2], t[:, 0, 1], t[:, 1, 2], t[:, 2, 0]], axis=1)


def frobenius(v: np.ndarray) -> np.ndarray:
    """(T,) Frobenius norm of Voigt tensors given with tensor (not engineering) shear components."""
    return np.sqrt(np.sum(v[:, :3] ** 2, axis=1) + 2.0 * np.sum(v[:, 3:] ** 2, axis=1))


class ElementOperators:
    """Strain ``B``, stress ``S`` and load ``f`` operators of a linear tet mesh (see module doc).

    ``nodes`` (N,3) m rest positions, ``tets`` (T,4), per-tet ``young`` (Pa) and ``poisson``;
    ``kappa_node`` (N,) Pa: nodal bulk moduli of the ANP formulation (default: volume-weighted
    average of the element values, as the FEM model does).
    """

    def __init__(self, nodes, tets, young, poisson, formulation: str = "standard", kappa_node=None):
        self.nodes = np.array(nodes, dtype=np.float64)
        self.tets = np.ascontiguousarray(tets, dtype=np.int64)
        n = len(nodes)
        self.n_nodes = n
        grads, self.volume, _ = asm.shape_gradients(nodes, self.tets)
        t = len(self.tets)
        b = asm.b_matrices(grads)                                   # (T, 6, 12)
        rows = np.repeat((6 * np.arange(t)[:, None] + np.arange(6)[None, :]), 12, axis=1)   # (T, 72)
        cols = np.tile(asm.element_dofs(self.tets), (1, 6))                                   # (T, 72)
        self.B = sp.csr_matrix((b.reshape(t, 72).ravel(), (rows.ravel(), cols.ravel())), shape=(6 * t, 3 * n))
        self.BT = self.B.T.tocsr()
        young = np.broadcast_to(np.asarray(young, dtype=np.float64), (t,))
        poisson = np.broadcast_to(np.asarray(poisson, dtype=np.float64), (t,))
        self.young, self.poisson = np.array(young), np.array(poisson)
        self.mu, self.lam, self.kappa = asm.lame_parameters(young, poisson)
        self.formulation = formulation
        self.compliance = np.ascontiguousarray(np.linalg.inv(asm.d_matrices(young, poisson)))   # Hooke D^-1
        if formulation == "anp":
            self.d = np.ascontiguousarray(asm.deviatoric_d_matrices(young, poisson))
            self.node_volume = asm.nodal_volumes(self.tets, self.volume, n)
            if kappa_node is None:
                kappa_node = asm.nodal_average(self.tets, self.volume, self.kappa, n)
            self.kappa_node = np.asarray(kappa_node, dtype=np.float64)
            # theta = A tr(eps): A[a, e] = (V_e / 4) / V_a ; pbar = P p: P[e, a] = 1/4
            tr_rows = self.tets.ravel()
            tr_cols = np.repeat(np.arange(t), 4)
            self._avg = sp.csr_matrix((np.repeat(self.volume / 4.0, 4) / self.node_volume[tr_rows], (tr_rows, tr_cols)),
                                      shape=(n, t))
            self._pbar = sp.csr_matrix((np.full(4 * t, 0.25), (tr_cols, tr_rows)), shape=(t, n))
        elif formulation == "standard":
            self.d = np.ascontiguousarray(asm.d_matrices(young, poisson))
        else:
            raise ValueError(f"formulation must be 'standard' or 'anp', got {formulation!r}")

    @classmethod
    def from_model(cls, model) -> "ElementOperators":
        """Operators of a :class:`~surgsim_envs.tissue.fem.TetFEMModel` (its rest mesh, current material
        fields and formulation; nodal bulk moduli averaged from the fields as the model does)."""
        return cls(model.rest_positions, model.tets, model.fields["young"], model.fields["poisson"], model.formulation)

    @property
    def n_elements(self) -> int:
        return len(self.tets)

    def strain(self, u: np.ndarray) -> np.ndarray:
        """(T,6) Voigt strain (engineering shear) of nodal displacements u (N,3) or (3N,) m."""
        return (self.B @ np.ravel(u)).reshape(-1, 6)

    def stress(self, eps: np.ndarray) -> np.ndarray:
        """(T,6) Voigt stress (Pa) of a Voigt strain field (engineering shear)."""
        sig = np.einsum("tij,tj->ti", self.d, eps)
        if self.formulation == "anp":
            theta = self._avg @ (eps[:, 0] + eps[:, 1] + eps[:, 2])
            sig[:, :3] += (self._pbar @ (self.kappa_node * theta))[:, None]
        return sig

    def hooke_strain(self, sig: np.ndarray) -> np.ndarray:
        """(T,6) Voigt strain (engineering shear) whose Hooke stress (paper eq. 2) is ``sig``."""
        return np.einsum("tij,tj->ti", self.compliance, sig)

    def in_stress_space(self, sig: np.ndarray) -> np.ndarray:
        """``S(D^-1 sig)``: a Hooke stress field expressed in this formulation's stresses (identity for
        "standard"; for "anp" the pressure becomes the averaged nodal pressure of the same strain),
        so that it carries no part that the formulation cannot stress."""
        return self.stress(self.hooke_strain(sig))

    def forces(self, sig: np.ndarray) -> np.ndarray:
        """(3N,) nodal forces (N) ``sum_e V_e B_e^T sigma_e`` of a Voigt stress field (Pa)."""
        return self.BT @ (self.volume[:, None] * sig).ravel()

    def stiffness(self) -> sp.csr_matrix:
        """Global stiffness ``B^T V S B`` (3N,3N) N/m (for meshes without a model)."""
        t = self.n_elements
        rows = np.repeat(6 * np.arange(t)[:, None] + np.arange(6)[None, :], 6, axis=1).ravel()
        cols = np.tile(6 * np.arange(t)[:, None] + np.arange(6)[None, :], (1, 6)).ravel()
        blocks = sp.csr_matrix(((self.volume[:, None, None] * self.d).ravel(), (rows, cols)), shape=(6 * t, 6 * t))
        k = self.BT @ blocks @ self.B
        if self.formulation == "anp":
            tr = self.B[0::6] + self.B[1::6] + self.B[2::6]          # (T, 3N): tr(eps_e) = row e
            bv = self._avg @ tr                                     # (N, 3N): theta = bv u
            k = k + bv.T @ sp.diags(self.kappa_node * self.node_volume) @ bv
        return k.tocsr()
