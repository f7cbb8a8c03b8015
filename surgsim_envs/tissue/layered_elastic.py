"""The ``layered`` model's ``stiffness="elastic"`` option: elasticity of the snapped cells in place of
the paper's scalar springs, inside the same constrained static solve (Lin et al. 2008, eqs. 2.5, 2.9).

Why (docs/models/layered.md, "Accuracy against FEM"): eq. 2.8's springs are one scalar Laplacian
for x, y and z; on the abdominal wall the thin stiff skin then acts as a membrane and the confined
near-incompressible fat is too soft (1.21 x FEM at the converged resolution), and no volume term
or calibrated scalar network fixes both. Here every node's stiffness block is the 3 x 3 coupled
stiffness of linear elasticity of the snapped lattice cells (each tet with its layer's E, nu):
``K = sum_t B_t^T D_dev,t B_t V_t + sum_c kappa_c V_c b_c^T b_c``, the shear part per Kuhn tet and
the volume part per lattice cell on the cell's mean dilatation ``theta_c = b_c u`` (the mean-
dilatation / B-bar hexahedron, Nagtegaal, Parks & Rice 1974; Hughes 1980: a per-tet volume term
locks the near-incompressible fat, 25 % too stiff at nu 0.49). The volume term couples only the 8
nodes of a cell, so the matrix keeps the lattice's 27-node stencil; ``fem``'s averaged nodal
pressure (the FEM reference) couples two rings and its factor fills 2.6 x more (measured, dd 4 mm
wall: 23 M vs 8.8 M LU entries, 13 s vs 3.8 s). It is a different discretisation from the FEM
reference, so the comparison against it is a test.

Kept from the paper's model: the layered volume (snapping, layers, bone fixed), the neighbouring
bounding boxes with the extreme lengths ``lmin`` (a spring compressed to ``lmin`` becomes a rigid
link whose force is passed on: eq. 2.5, stored in ``push`` as the scalar model stores it, so
``contact_force`` reads it the same way) and the quasi-static equilibrium per step with Dirichlet
contact nodes or implicit contact stiffness. Interface-only materials (a layer of springs on an
interface with no tets of its own, e.g. the fascia) have no cells, so they are absent here.

Solver (:class:`ElasticContact`): the stiffness of every node except the ANCHORS (Dirichlet nodes
at rest: bonded faces, bone) is factorised once; ``g_d = K^-1 e_d`` is back-solved the first time
dof d carries a load and cached. With the loaded dofs D (held contact nodes, penalty-contact nodes,
externally loaded nodes, rigid-link ends) ``u = v0 + G_D f_D``; the unknown reactions z (held
nodes' forces, penalty forces, link forces) solve the small symmetric system
``(M^T G_DD M + diag(0, 1/kc, 0)) z = rhs``; the rigid links come from an active-set iteration
warm-started from the previous step. Exact for the linear elastic network; every node is written
each step (O(3N |D|)), so it is slower than the scalar model's lazy prefactored step (measured in
docs/models/layered.md). Units: m, N, N/m, Pa.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from surgsim_envs.errors import ConfigError
from surgsim_envs.tissue import fem_assembly as asm
from surgsim_envs.tissue.layered_block import INFEASIBLE, MAX_ACTIVE_SET_ITERS

#: a pair closer than its extreme length by more than this fraction of it joins as a rigid link
LINK_TOL = 1e-9


def cell_of_tets(lattice_index: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """(T,) lattice cell of each Kuhn tet (its nodes' smallest lattice coordinates), numbered 0..C-1."""
    corner = np.asarray(lattice_index, dtype=np.int64)[np.asarray(tets, dtype=np.int64)].min(axis=1)
    return np.unique(corner, axis=0, return_inverse=True)[1].ravel()


def elastic_stiffness(rest: np.ndarray, tets: np.ndarray, young: np.ndarray, poisson: np.ndarray,
                      cells: np.ndarray) -> sp.csr_matrix:
    """3N x 3N (node-major dofs, N/m) linear-elastic stiffness of the snapped cells: the shear
    (deviatoric) part per tet, the volume part per lattice cell on the cell's mean dilatation
    ``theta_c = sum_(t in c) V_t div_t u / V_c`` with ``kappa_c`` the volume-weighted mean of its tets'
    bulk moduli (mean-dilatation / B-bar cell, as Q1-P0 hexahedra: no volumetric locking of the
    near-incompressible fat; couples only the cell's 8 nodes). ``cells`` (T,) the cell of each tet."""
    n = len(rest)
    tets = np.asarray(tets, dtype=np.int64)
    grads, vols, _ = asm.shape_gradients(rest, tets)
    ke = asm.element_stiffness(asm.b_matrices(grads), asm.deviatoric_d_matrices(young, poisson), vols)
    _, _, kappa = asm.lame_parameters(young, poisson)
    n_cells = int(cells.max()) + 1
    vc = np.bincount(cells, weights=vols, minlength=n_cells)
    kc = np.bincount(cells, weights=vols * kappa, minlength=n_cells) / vc
    val = ((vols / vc[cells])[:, None, None] * grads).ravel()
    bc = sp.coo_matrix((val, (np.repeat(cells, 12), asm.element_dofs(tets).ravel())), shape=(n_cells, 3 * n)).tocsr()
    return (asm.assemble(tets, ke, n) + bc.T @ sp.diags(kc * vc) @ bc).tocsr()


class ElasticContact:
    """All-node constrained equilibrium of a LayeredModel with ``stiffness="elastic"`` (module docstring).

    Built for the model's current anchors (fixed nodes held at rest); :meth:`valid` tells whether
    they still are."""

    def __init__(self, model):
        self.model = model
        n = model.n_nodes
        self.k = model._elastic_k
        at_rest = np.all(model.fixed_targets == model.rest_positions, axis=1)
        self.anchor = model.fixed & at_rest
        free_nodes = np.flatnonzero(~self.anchor)
        if len(free_nodes) == 0:
            raise ConfigError("layered: every node is anchored; free some nodes")
        self.free_dofs = (3 * free_nodes[:, None] + np.arange(3)).ravel()
        self.local = np.full(3 * n, -1, dtype=np.int64)
        self.local[self.free_dofs] = np.arange(len(self.free_dofs))
        kff = self.k[self.free_dofs][:, self.free_dofs].tocsc()
        self.lu = spla.splu(kff, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
        self._cols: dict[int, np.ndarray] = {}
        # anchors are at rest: v0 (their response) is zero
        self.v0 = np.zeros(3 * n)
        # candidate rigid links: (lower node i, upper node j, axis a, lmin)
        ii, jj, aa, lm = [], [], [], []
        for a in range(3):
            j = model.nbr[:, 2 * a + 1].astype(np.int64)
            i = np.flatnonzero(j >= 0)
            ii.append(i)
            jj.append(j[i])
            aa.append(np.full(len(i), a))
            lm.append(model.lmin[i, 2 * a + 1])
        self.li, self.lj = np.concatenate(ii), np.concatenate(jj)
        self.la, self.llmin = np.concatenate(aa), np.concatenate(lm)
        # rest separation minus lmin: u_j,a - u_i,a >= -s0 keeps the pair at or beyond lmin
        rest = model.rest_positions
        self.ls0 = rest[self.lj, self.la] - rest[self.li, self.la] - self.llmin
        self.active = np.zeros(len(self.li), dtype=bool)
        self.last_iterations = 0

    def valid(self) -> bool:
        m = self.model
        at_rest = np.all(m.fixed_targets == m.rest_positions, axis=1)
        return bool(np.array_equal(self.anchor, m.fixed & at_rest)) and m._elastic_k is self.k

    def _col(self, d: int) -> np.ndarray:
        c = self._cols.get(d)
        if c is None:
            e = np.zeros(len(self.free_dofs))
            e[self.local[d]] = 1.0
            c = np.zeros(len(self.local))
            c[self.free_dofs] = self.lu.solve(e)
            self._cols[d] = c
        return c

    def solve(self, ext: np.ndarray, kc: np.ndarray, xs: np.ndarray) -> bool:
        """Write the equilibrium positions and link pushes into the model under external forces
        ``ext`` (N,3) N and implicit contact stiffness ``kc`` (N,) N/m about ``xs`` (N,3) m; True when
        the rigid links settled."""
        m = self.model
        rest = m.rest_positions
        held = np.flatnonzero(m.fixed & ~self.anchor)
        pen = np.flatnonzero((kc > 0) & ~m.fixed)
        loaded = np.flatnonzero(np.any(ext != 0.0, axis=1) & ~m.fixed & ~(kc > 0))
        u_held = (m.fixed_targets[held] - rest[held]).ravel()
        dofs3 = lambda nodes: (3 * nodes[:, None] + np.arange(3)).ravel()  # noqa: E731
        hd, pd, ed = dofs3(held), dofs3(pen), dofs3(loaded)
        kc_d = np.repeat(kc[pen], 3)
        target_p = (xs[pen] - rest[pen]).ravel()
        active = self.active & ~(m.fixed[self.li] & m.fixed[self.lj])
        settled = False
        u = None
        for it in range(MAX_ACTIVE_SET_ITERS):
            links = np.flatnonzero(active)
            ld_i = 3 * self.li[links] + self.la[links]
            ld_j = 3 * self.lj[links] + self.la[links]
            D, inv = np.unique(np.concatenate([hd, pd, ed, ld_i, ld_j]), return_inverse=True)
            D = D[self.local[D] >= 0]  # anchored dofs carry no displacement
            pos = {int(d): q for q, d in enumerate(D)}
            G = np.stack([self._col(int(d)) for d in D], axis=1) if len(D) else np.zeros((len(self.local), 0))
            gdd = G[D]
            # M: columns of unknowns (held dofs, penalty dofs, links) over D
            nz = len(hd) + len(pd) + len(links)
            M = np.zeros((len(D), nz))
            for q, d in enumerate(hd):
                M[pos[int(d)], q] = 1.0
            for q, d in enumerate(pd):
                M[pos[int(d)], len(hd) + q] = 1.0
            off = len(hd) + len(pd)
            for q in range(len(links)):
                if int(ld_j[q]) in pos:
                    M[pos[int(ld_j[q])], off + q] += 1.0
                if int(ld_i[q]) in pos:
                    M[pos[int(ld_i[q])], off + q] -= 1.0
            f0 = np.zeros(len(D))
            for d, v in zip(ed, ext[loaded].ravel()):
                f0[pos[int(d)]] += v
            for d, v in zip(pd, ext[pen].ravel()):
                f0[pos[int(d)]] += v
            W = M.T @ gdd @ M
            W[np.arange(len(hd), off), np.arange(len(hd), off)] += 1.0 / kc_d
            # right-hand side: held displacements, penalty anchors, link separations (anchored ends at 0)
            s_link = -self.ls0[links]
            rhs = np.concatenate([u_held, target_p, s_link]) - M.T @ (gdd @ f0)
            z = np.linalg.solve(W, rhs) if nz else np.zeros(0)
            f = f0 + M @ z
            u = G @ f
            lam = z[off:]
            gap = (u[3 * self.lj + self.la] - u[3 * self.li + self.la]) + self.ls0
            new = active.copy()
            new[links[lam < 0.0]] = False
            new |= (gap < -LINK_TOL * self.llmin) & ~(m.fixed[self.li] & m.fixed[self.lj])
            self.last_iterations = it + 1
            if np.array_equal(new, active):
                settled = True
                break
            active = new
        self.active = active
        x = rest + u.reshape(-1, 3)
        links = np.flatnonzero(active)
        if len(links):  # a link squeezed well past its extreme length: the press is infeasible
            over = -((u[3 * self.lj[links] + self.la[links]] - u[3 * self.li[links] + self.la[links]])
                     + self.ls0[links]) / self.llmin[links]
            if over.max() > INFEASIBLE:
                raise ConfigError(
                    f"layered: springs fully compressed from the contact to a fixed node (a rigid link squeezed "
                    f"{over.max():.0%} past its extreme length); the press is deeper than the tissue can give "
                    f"(at most {1 - m.max_compression:.0%} of it remains): reduce the depth")
        m._x[:] = x
        fx = np.flatnonzero(m.fixed)
        m._x[fx] = m.fixed_targets[fx]
        m.push[:] = 0.0
        if len(links):
            lam_pos = np.maximum(lam, 0.0) if len(lam) == len(links) else np.zeros(len(links))
            m.push[self.li[links], 2 * self.la[links] + 1] = lam_pos
            m.push[self.lj[links], 2 * self.la[links]] = lam_pos
        # the contact force actually integrated on the penalty nodes
        m.integrated_external_forces[:] = 0.0
        m.integrated_external_forces[loaded] = ext[loaded]
        m.integrated_external_forces[pen] = ext[pen] + kc[pen, None] * (xs[pen] - m._x[pen])
        return settled


def elastic_forces(model, nodes: np.ndarray) -> np.ndarray:
    """(K,3) N internal force on ``nodes``: -(K u) of the elastic cells plus the rigid links' pushes."""
    u = (model.positions - model.rest_positions).ravel()
    dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
    out = -(model._elastic_k[dofs] @ u).reshape(-1, 3)
    push, nbr = model.push, model.nbr
    for d in range(6):
        j = nbr[nodes, d]
        ok = j >= 0
        pin = np.where(ok, push[np.where(ok, j, 0), d ^ 1], 0.0)
        a = d // 2
        out[:, a] += np.where(pin > 0, pin if (d ^ 1) & 1 else -pin, 0.0)
    return out


__all__ = ["ElasticContact", "elastic_stiffness", "elastic_forces"]
