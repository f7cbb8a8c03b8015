"""Direct constrained solve of the ``layered`` model on a block of nodes (Lin et al. 2008, eqs. 2.5-2.9).

The local static integration of :mod:`surgsim_envs.tissue.layered_kernels` (a projected
Gauss-Seidel over the active nodes) converges slowly where stiff skin lies over soft fat: a
displacement spreads through the skin in one sweep per lattice spacing. This module solves the
same equilibrium for a BLOCK of free nodes at once, the nodes outside the block (and the
Dirichlet nodes inside) held where they are:

* springs (eq. 2.8): ``sum_j K_ij (u_j - u_i) + g_i + kc_i (xs_i - x_i) = 0`` is one scalar graph
  Laplacian ``A`` shared by the x, y and z displacements, factorised once per block (sparse LU);
* extreme lengths (Fig. 2.10): a spring compressed to ``lmin`` is rigid. Active-set iteration: a
  pair whose axis separation falls below ``lmin`` gets a stiff link (``RIGID_FACTOR`` x the largest
  spring constant) that holds it at ``lmin``; a link in tension is released; repeat until the set
  is stable. The link's force is the force passed on (the accumulation of eq. 2.5) and is stored
  in ``push`` exactly as the local iteration stores it, so ``contact_force`` reads it the same way.

Used by :meth:`LayeredModel.static_solve` (the all-node solution: the block is every free node)
and as the fallback of :class:`~surgsim_envs.tissue.layered_prefactored.PrefactoredContact` (the
"prefactored" per-step solver) when a
spring reaches its extreme length. (A per-step block of the nodes near the load with the rest
held was tried: 27 ms per step and 2-5 % off the all-node force on an 18k-node wall, because a
contact node joining or leaving moves the skin far beyond the block.) Units: m, N, N/m.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

#: stiffness of a rigid (extreme-length) link relative to the largest spring constant
RIGID_FACTOR = 1e4
#: relative squeeze of a rigid link past its extreme length that means no feasible state exists
INFEASIBLE = 0.05
#: active-set iterations before giving up (the model then reports them as unconverged)
MAX_ACTIVE_SET_ITERS = 40


def laplacian(nbr: np.ndarray, kk: np.ndarray) -> sp.csr_matrix:
    """Scalar stiffness (N x N, N/m) of the NBB springs: diag(sum_j K_ij) - K."""
    n = len(nbr)
    i_idx, d_idx = np.nonzero(nbr >= 0)
    j = nbr[i_idx, d_idx]
    k = kk[i_idx, d_idx]
    return (sp.coo_matrix((-k, (i_idx, j)), shape=(n, n)).tocsr() + sp.diags(kk.sum(axis=1))).tocsr()


class BlockSolver:
    """Direct constrained equilibrium of the free nodes ``block`` (int array) of a LayeredModel.

    The factorisations depend on the block, the Dirichlet nodes in it, ``kc`` and the rigid links;
    they are cached until one of these changes (:meth:`solve` checks)."""

    def __init__(self, model, block: np.ndarray):
        self.model = model
        self.block = np.asarray(block, dtype=np.int64)
        n = model.n_nodes
        self.local = np.full(n, -1, dtype=np.int64)
        self.local[self.block] = np.arange(len(self.block))
        lap = model._laplacian()
        self._a0 = lap[self.block][:, self.block].tocsc()
        outside = np.ones(n, dtype=bool)
        outside[self.block] = False
        self._held = np.flatnonzero(outside)
        self._k_held = (-lap[self.block][:, self._held]).tocsr()
        self._lu = {}
        self._kc_key = None
        self.k_rigid = RIGID_FACTOR * float(model.kk.max())
        # candidate links: every pair (i below j along axis a) with at least one end in the block
        self._pairs = []
        for a in range(3):
            j = model.nbr[:, 2 * a + 1].astype(np.int64)
            i = np.arange(n)
            ok = (j >= 0)
            ok[ok] = (self.local[i[ok]] >= 0) | (self.local[j[ok]] >= 0)
            self._pairs.append((i[ok], j[ok], model.lmin[i[ok], 2 * a + 1]))
        self.last_iterations = 0

    def _factor(self, a: int, kc: np.ndarray, active: np.ndarray):
        """LU of axis ``a``'s block matrix with the rigid links ``active`` (bool over pairs)."""
        key = (a if active.any() else -1, active.tobytes() if active.any() else b"")
        lu = self._lu.get(key)
        if lu is not None:
            return lu
        m = self._a0 + sp.diags(kc[self.block])
        if active.any():
            i, j, _ = self._pairs[a]
            li, lj = self.local[i[active]], self.local[j[active]]
            kr = self.k_rigid
            both = (li >= 0) & (lj >= 0)
            rows = np.concatenate([li[li >= 0], lj[lj >= 0], li[both], lj[both]])
            cols = np.concatenate([li[li >= 0], lj[lj >= 0], lj[both], li[both]])
            vals = np.concatenate([np.full((li >= 0).sum() + (lj >= 0).sum(), kr), np.full(2 * both.sum(), -kr)])
            m = m + sp.coo_matrix((vals, (rows, cols)), shape=m.shape)
        if len(self._lu) > 16:
            self._lu.clear()
        lu = spla.splu(m.tocsc(), permc_spec="MMD_AT_PLUS_A")
        self._lu[key] = lu
        return lu

    def solve(self, ext: np.ndarray, kc: np.ndarray, xs: np.ndarray) -> bool:
        """Equilibrium of the block (positions and ``push`` of the model updated in place) under
        external forces ``ext`` (N,3) N and implicit contact stiffness ``kc`` (N,) about ``xs``.
        Returns True when the active set of rigid links settled."""
        model = self.model
        blk = self.block
        kc_key = kc[blk].tobytes()
        if kc_key != self._kc_key:
            self._lu.clear()
            self._kc_key = kc_key
        x = model.positions
        rest = model.rest_positions
        u_held = x[self._held] - rest[self._held]
        base = self._k_held @ u_held + ext[blk] + kc[blk, None] * (xs[blk] - rest[blk])
        active = [np.zeros(len(p[0]), dtype=bool) for p in self._pairs]
        settled = False
        lam = [np.zeros(len(p[0])) for p in self._pairs]
        for it in range(MAX_ACTIVE_SET_ITERS):
            changed = False
            for a in range(3):
                i, j, lmin = self._pairs[a]
                rhs = base[:, a].copy()
                act = active[a]
                if act.any():
                    ia, ja = i[act], j[act]
                    li, lj = self.local[ia], self.local[ja]
                    # link energy 0.5 kr (u_j - u_i + s0)^2, s0 = rest separation - lmin; held ends known
                    s0 = rest[ja, a] - rest[ia, a] - lmin[act]
                    ui = np.where(li >= 0, 0.0, x[ia, a] - rest[ia, a])
                    uj = np.where(lj >= 0, 0.0, x[ja, a] - rest[ja, a])
                    np.add.at(rhs, li[li >= 0], (self.k_rigid * (s0 + uj))[li >= 0])
                    np.add.at(rhs, lj[lj >= 0], (self.k_rigid * (ui - s0))[lj >= 0])
                u = self._factor(a, kc, act).solve(rhs)
                x[blk, a] = rest[blk, a] + u
                gap = x[j, a] - x[i, a] - lmin
                lam[a] = np.where(act, -self.k_rigid * gap, 0.0)
                new = (act & (lam[a] > 0.0)) | (~act & (gap < -1e-12))
                if not np.array_equal(new, act):
                    active[a] = new
                    changed = True
            self.last_iterations = it + 1
            if not changed:
                settled = True
                break
        for a in range(3):  # a link squeezed well past its extreme length: the press is infeasible
            i, j, lmin = self._pairs[a]
            act = active[a]
            if act.any():
                over = (x[i[act], a] + lmin[act] - x[j[act], a]) / lmin[act]
                if over.max() > INFEASIBLE:
                    from surgsim_envs.errors import ConfigError

                    raise ConfigError(
                        f"layered: springs fully compressed from the contact to a fixed node (a rigid link "
                        f"squeezed {over.max():.0%} past its extreme length); the press is deeper than the "
                        f"tissue can give (at most {1 - model.max_compression:.0%} of it remains): reduce the depth")
        # forces passed on by the rigid links (eq. 2.5), as the local iteration stores them
        push = model.push
        push[blk] = 0.0
        for a in range(3):
            i, j, _ = self._pairs[a]
            act = active[a]
            if act.any():
                f = np.maximum(lam[a][act], 0.0)
                push[i[act], 2 * a + 1] = f
                push[j[act], 2 * a] = f
        return settled


__all__ = ["BlockSolver", "laplacian", "RIGID_FACTOR", "MAX_ACTIVE_SET_ITERS"]
