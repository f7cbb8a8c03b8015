"""Direct constrained solve of the ``layered`` model on a block of nodes (paper 001, eqs. 2.5-2.9).

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
and as the fallback of :class:`PrefactoredContact` (the "prefactored" per-step solver) when a
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


class PrefactoredContact:
    """All-node equilibrium of the springs with moving Dirichlet (contact) nodes, per step in
    O(region x contacts): the spring Laplacian ``A`` of every node except the ANCHORS (the nodes
    fixed when it was built: bonded faces, bone) is factorised once; a contact node c held at
    displacement t_c adds a reaction lambda_c, so ``u = v0 + sum_c g_c lambda_c`` with
    ``g_c = A^-1 e_c`` (one solve the first time c is held, then cached) and ``v0`` the response to
    the anchors (Dirichlet nodes held at their rest positions when it was built); the held displacements give ``G_CC lambda = t_C - v0_C`` (|C| x |C|, the x, y, z
    components share it). Exact for the linear springs (eq. 2.8); nodes within ``radius`` m of the
    contact are written each step (the far field every ``refresh`` steps). A spring of that region
    at its extreme length becomes a rigid link with its own reaction (a column ``g_j - g_i`` of its
    axis), found by the same active-set iteration as :class:`BlockSolver` and warm-started from the
    previous step's links; the link reactions are the accumulated pushes. It does not apply with
    external forces or implicit contact stiffness (the caller uses the local iteration then).
    """

    def __init__(self, model, radius: float, refresh: int = 50):
        self.model = model
        n = model.n_nodes
        # anchors: Dirichlet nodes held at rest (bonded faces, bone); the others are contacts
        self.anchor = model.fixed & np.all(model.fixed_targets == model.rest_positions, axis=1)
        self.anchor_idx = np.flatnonzero(self.anchor)
        self.anchor_targets = model.fixed_targets[self.anchor_idx].copy()
        self.free = np.flatnonzero(~self.anchor)
        self.local = np.full(n, -1, dtype=np.int64)
        self.local[self.free] = np.arange(len(self.free))
        lap = model._laplacian()
        a = lap[self.free][:, self.free].tocsc()
        self.lu = spla.splu(a, permc_spec="MMD_AT_PLUS_A")
        u_anchor = self.anchor_targets - model.rest_positions[self.anchor_idx]
        self.v0 = self.lu.solve(np.ascontiguousarray(-(lap[self.free][:, self.anchor_idx] @ u_anchor)))
        self.slot: dict[int, int] = {}
        self.G = np.zeros((len(self.free), 16))   # column k: A^-1 e_c of the node in slot k
        self._gr = None                             # G restricted to the region's rows
        self.radius = float(radius)
        self.refresh = int(refresh)
        self._region = None
        self._steps = 0
        self.last_region = 0

    def valid(self) -> bool:
        """False once an anchor was released or moved (the factorisation no longer applies)."""
        m = self.model
        return bool(m.fixed[self.anchor_idx].all()) and np.array_equal(m.fixed_targets[self.anchor_idx],
                                                                       self.anchor_targets)

    def _slots(self, contact: np.ndarray) -> np.ndarray:
        """Slots of ``contact`` in ``G``; solves (and stores) the columns of new contact nodes."""
        out = np.empty(len(contact), dtype=np.int64)
        for q, c in enumerate(contact.tolist()):
            k = self.slot.get(c)
            if k is None:
                k = self.slot[c] = len(self.slot)
                if k >= self.G.shape[1]:
                    self.G = np.concatenate([self.G, np.zeros_like(self.G)], axis=1)
                e = np.zeros(len(self.free))
                e[self.local[c]] = 1.0
                self.G[:, k] = self.lu.solve(e)
                self._gr = None
            out[q] = k
        return out

    def _region_nodes(self, contact: np.ndarray) -> np.ndarray:
        m = self.model
        idx = m.volume.lattice_index
        lo, hi = idx[contact].min(axis=0), idx[contact].max(axis=0)
        r = int(np.ceil(self.radius / m.volume.spacing))
        reg = self._region
        if reg is None or np.any((lo - reg[0])[:2] < r // 2) or np.any((reg[1] - hi)[:2] < r // 2):
            b_lo, b_hi = lo - r, hi + r
            b_lo[2], b_hi[2] = idx[:, 2].min(), idx[:, 2].max()   # whole columns: a press loads the full depth
            nodes = np.flatnonzero(np.all((idx >= b_lo) & (idx <= b_hi), axis=1) & ~self.anchor)
            reg = self._region = (b_lo, b_hi, nodes, self.local[nodes])
            self._gr = None
        return reg

    def solve(self) -> tuple[np.ndarray, bool]:
        """Write the equilibrium positions, rigid links included; returns (nodes written, settled)."""
        m = self.model
        contact = np.flatnonzero(m.fixed & ~self.anchor)
        x, rest = m.positions, m.rest_positions
        self._steps += 1
        if len(contact) == 0:
            nodes = self.free
            self.before = x[nodes].copy()
            x[nodes] = rest[nodes] + self.v0
            self.links = [np.zeros((0, 2), dtype=np.int64) for _ in range(3)]
            self.last_region = len(nodes)
            return nodes, True
        full = self._steps % self.refresh == 0
        if full:
            nodes, rows = self.free, np.arange(len(self.free))
        else:
            _, _, nodes, rows = self._region_nodes(contact)
        self.before = x[nodes].copy()
        in_region = np.zeros(m.n_nodes, dtype=bool)
        in_region[nodes] = True
        in_region[contact] = True
        links = getattr(self, "links", None) or [np.zeros((0, 2), dtype=np.int64) for _ in range(3)]
        t_all = m.fixed_targets[contact] - rest[contact]
        settled = False
        for it in range(MAX_ACTIVE_SET_ITERS):
            changed = False
            new_links = []
            for a in range(3):
                lk = links[a]
                lk = lk[~self.anchor[lk[:, 0]] | ~self.anchor[lk[:, 1]]] if len(lk) else lk
                ends = np.concatenate([contact, lk[:, 0], lk[:, 1]]) if len(lk) else contact
                ends = ends[~self.anchor[ends]]
                uniq = np.unique(ends)
                slots = self._slots(uniq)
                pos = {int(c): q for q, c in enumerate(uniq.tolist())}
                nc, nl = len(contact), len(lk)
                # constraint rows as combinations of the unique nodes' displacements
                E = np.zeros((nc + nl, len(uniq)))
                E[np.arange(nc), [pos[int(c)] for c in contact]] = 1.0
                for q, (i, j) in enumerate(lk.tolist()):
                    if not self.anchor[j]:
                        E[nc + q, pos[j]] += 1.0
                    if not self.anchor[i]:
                        E[nc + q, pos[i]] -= 1.0
                lu_rows = self.local[uniq]
                guu = self.G[lu_rows][:, slots]                 # (U, U): u at uniq from unit loads at uniq
                v0u = self.v0[lu_rows, a]
                rhs = np.concatenate([t_all[:, a], -(rest[lk[:, 1], a] - rest[lk[:, 0], a]
                                                     - m.lmin[lk[:, 0], 2 * a + 1])]) if nl else t_all[:, a].copy()
                M = E @ guu @ E.T
                lam = np.linalg.solve(M, rhs - E @ v0u)
                w = E.T @ lam                                   # load on each unique node
                if full:
                    gcols = self.G[:, slots]
                else:
                    if self._gr is None or self._gr.shape[1] < len(self.slot):
                        self._gr = self.G[rows, :len(self.slot)].copy()
                    gcols = self._gr[:, slots]
                x[nodes, a] = rest[nodes, a] + self.v0[rows, a] + gcols @ w
                x[contact, a] = m.fixed_targets[contact, a]
                mu = lam[nc:]
                keep = lk[mu > 0.0] if nl else lk
                # springs of the region shorter than their extreme length join as rigid links
                j = m.nbr[nodes, 2 * a + 1]
                ok = (j >= 0)
                ok[ok] = in_region[j[ok]]
                ii, jj = nodes[ok], j[ok].astype(np.int64)
                gap = x[jj, a] - x[ii, a] - m.lmin[ii, 2 * a + 1]
                viol = gap < -1e-9 * m.lmin[ii, 2 * a + 1]
                add = np.stack([ii[viol], jj[viol]], axis=1)
                nl_new = np.unique(np.concatenate([keep, add]), axis=0) if len(add) else keep
                n = m.n_nodes
                if not np.array_equal(np.sort(nl_new[:, 0] * n + nl_new[:, 1]), np.sort(lk[:, 0] * n + lk[:, 1])):
                    changed = True
                new_links.append(nl_new.astype(np.int64))
                if a == 0:
                    self._last_push = []
                self._last_push.append((lk, mu))
            links = new_links
            if not changed:
                settled = True
                break
        self.links = links
        m.push[nodes] = 0.0
        m.push[contact] = 0.0
        for a, (lk, mu) in enumerate(self._last_push):
            if len(lk):
                f = np.maximum(mu, 0.0)
                m.push[lk[:, 0], 2 * a + 1] = f
                m.push[lk[:, 1], 2 * a] = f
        self.last_region = len(nodes)
        self.last_iterations = it + 1
        return nodes, settled


def extreme_length_violated(model, nodes: np.ndarray) -> bool:
    """True if a spring at ``nodes`` is shorter along its axis than its extreme length."""
    x = model.positions
    for a in range(3):
        j = model.nbr[nodes, 2 * a + 1]
        ok = j >= 0
        if np.any(x[j[ok], a] - x[nodes[ok], a] < model.lmin[nodes[ok], 2 * a + 1]):
            return True
    return False
