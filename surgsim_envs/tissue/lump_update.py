"""The compliance of a lumpy body as a low-rank update of one shared compliance (Woodbury).

A task that draws a stiff lump and a Young's scale ``s`` per reset (Palpation-v0) has, on the free
dofs, ``K = s K0 + dK``: ``K0`` the body as built, ``dK`` non-zero only on the ``r`` dofs ``S`` of the
nodes the lump's elements (and their averaged nodal pressure) touch. With the dense ``C0 = K0^-1``,
computed once and shared by every world, Woodbury's identity gives the world's compliance columns
without factorising ``K``::

    C[:, A] = (C0[:, A] - C0[:, S] D M^-1 C0[S, A]) / s,   D = dK[S, S] / s,   M = I + C0[S, S] D

``M`` is ``r x r`` with eigenvalues >= 1 (``C0`` is positive definite, ``D`` positive semi-definite
for a lump stiffer than the body), so its LU is well conditioned. Per world this keeps ``S``, ``D``
and the LU of ``M`` (``2 r^2`` floats). The host-side form of what a batched quasi-static world would
compute on the device (docs/batch.md, "Not batched yet"). Units: stiffness N/m, compliance m/N.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from surgsim_envs.errors import ConfigError

#: entries of dK below this share of K's largest entry are the scaling's rounding, not the lump
DROP = 1e-9


def dense_compliance(k_free: sp.spmatrix) -> np.ndarray:
    """``K^-1`` of a symmetric positive definite stiffness on the free dofs (dense, symmetrised), by one
    sparse factorisation and as many back-substitutions as dofs (m/N)."""
    k = sp.csc_matrix(k_free)
    if k.shape[0] != k.shape[1] or k.shape[0] == 0:
        raise ConfigError(f"dense_compliance: the stiffness must be square and non-empty, got shape {k.shape}")
    lu = spla.splu(k, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
    c = lu.solve(np.eye(k.shape[0]))
    return 0.5 * (c + c.T)


def stiffness_change(k_world: sp.spmatrix, k_unit: sp.spmatrix, scale: float, drop: float = DROP) -> sp.csr_matrix:
    """``dK = K_world - scale K_unit`` with the entries under ``drop`` x K_world's largest removed (the
    rounding of scaling every element), so that its non-zero rows are the lump's support."""
    dk = (sp.csr_matrix(k_world) - scale * sp.csr_matrix(k_unit)).tocsr()
    top = np.abs(sp.csr_matrix(k_world).data).max(initial=0.0)
    dk.data[np.abs(dk.data) < drop * top] = 0.0
    dk.eliminate_zeros()
    return dk


class LumpCompliance:
    """One world's compliance ``(s K0 + dK)^-1`` on the free dofs from the shared ``c0_unit = K0^-1``.

    c0_unit: (n, n) dense compliance of the body as built (shared, not copied). dk: (n, n) sparse
    ``K_world - scale K0`` (:func:`stiffness_change`). scale: the world's Young's scale (> 0)."""

    def __init__(self, c0_unit: np.ndarray, dk: sp.spmatrix, scale: float):
        n = c0_unit.shape[0] if getattr(c0_unit, "ndim", 0) == 2 else -1
        if n <= 0 or c0_unit.shape != (n, n):
            raise ConfigError(f"LumpCompliance: c0_unit must be a square (n, n) array, got shape "
                              f"{getattr(c0_unit, 'shape', None)}")
        if dk.shape != (n, n):
            raise ConfigError(f"LumpCompliance: dk has shape {dk.shape}, c0_unit {c0_unit.shape}; both are on the "
                              "same free dofs")
        if not (isinstance(scale, (int, float, np.floating)) and math.isfinite(scale) and scale > 0):
            raise ConfigError(f"LumpCompliance: scale={scale!r} must be a finite Young's scale > 0 (e.g. 1.0)")
        self.c0_unit, self.scale = c0_unit, float(scale)
        dk = sp.csr_matrix(dk)
        self.support = np.flatnonzero(np.diff(dk.indptr) > 0)
        s = self.support
        self.d = dk[s][:, s].toarray() / self.scale
        m = np.eye(len(s)) + c0_unit[np.ix_(s, s)] @ self.d
        self.lu = la.lu_factor(m) if len(s) else None

    @property
    def nbytes(self) -> int:
        """Bytes this world keeps beyond the shared ``c0_unit`` (support, D, LU of M)."""
        return int(self.support.nbytes + self.d.nbytes + (self.lu[0].nbytes + self.lu[1].nbytes if self.lu else 0))

    def _dofs(self, cols) -> np.ndarray:
        cols = np.asarray(cols)
        n = self.c0_unit.shape[0]
        if cols.ndim != 1 or not np.issubdtype(cols.dtype, np.integer) or (cols.size and (cols.min() < 0 or cols.max() >= n)):
            raise ConfigError(f"LumpCompliance: columns must be a 1-d array of free-dof indices in [0, {n}), got "
                              f"{cols.dtype} shape {cols.shape}")
        return cols

    def columns(self, cols) -> np.ndarray:
        """``C[:, cols]`` (n, len(cols)), m/N: the displacement of every free dof per unit force on each."""
        cols = self._dofs(cols)
        c0, s = self.c0_unit, self.support
        out = c0[:, cols].copy()
        if self.lu is not None:
            out -= c0[:, s] @ (self.d @ la.lu_solve(self.lu, c0[np.ix_(s, cols)]))
        return out / self.scale

    def block(self, cols) -> np.ndarray:
        """``C[cols, cols]``, m/N: what a contact solve on those dofs needs."""
        cols = self._dofs(cols)
        c0, s = self.c0_unit, self.support
        out = c0[np.ix_(cols, cols)].copy()
        if self.lu is not None:
            out -= c0[np.ix_(cols, s)] @ (self.d @ la.lu_solve(self.lu, c0[np.ix_(s, cols)]))
        return out / self.scale


__all__ = ["DROP", "dense_compliance", "stiffness_change", "LumpCompliance"]
