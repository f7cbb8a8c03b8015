"""The ``layered`` model's "prefactored" per-step solver: the all-node equilibrium of the springs
with moving contact nodes, touching only the contact region per step (Lin et al. 2008, eqs. 2.5, 2.8).

The spring Laplacian ``A`` of every node except the ANCHORS (Dirichlet nodes held at rest when it
was built: bonded faces, bone) is factorised once. A contact node c held at displacement t_c adds
a reaction lambda_c, so ``u = v0 + sum_c g_c lambda_c`` with ``g_c = A^-1 e_c`` (one back-solve the
first time c is held, then cached) and ``v0`` the anchors' response; the held displacements give
``G_CC lambda = t_C - v0_C`` (|C| x |C|, per axis). Exact for the linear springs (eq. 2.8). A spring
at its extreme length becomes a rigid link with its own reaction (a column ``g_j - g_i`` of its
axis), found by an active-set iteration warm-started from the previous step's links; the link
reactions are the accumulated pushes (eq. 2.5) that ``contact_force`` reads.

Per step (numba kernels in :mod:`layered_prefactored_kernels`) only the NEAR set is written: whole
lattice columns within ``near`` lattice spacings of the contact's footprint (the contact nodes'
neighbours for the force, the compressed column for the extreme-length check). The other nodes'
positions are recovered lazily (``LayeredModel.positions`` materialises them when read;
``LayeredModel.node_positions(idx)`` evaluates rows without writing). Each step also writes the
next piece of a round-robin sweep (two lattice slabs x = k, k + 1 cut along y into overlapping
pieces of ~``SWEEP_CHUNK`` nodes), so every node is written and finite-checked and every spring
checked against its extreme length once per sweep (about 240 steps on the 59k-node wall) without
a full write. Units: m, N, N/m.
"""

from __future__ import annotations

import atexit
import queue
import threading
import weakref

import numpy as np
import scipy.sparse.linalg as spla

from surgsim_envs.tissue import layered_prefactored_kernels as pk
from surgsim_envs.tissue.layered_block import MAX_ACTIVE_SET_ITERS

#: a spring shorter than its extreme length by more than this fraction of it joins as a rigid link
LINK_TOL = 1e-9
#: steps between checks that the anchors are unchanged (the factorisation still applies)
REFRESH = 50
#: nodes per piece of the round-robin sweep (:meth:`PrefactoredContact._sweep_chunks`)
SWEEP_CHUNK = 512


class RowPrefetcher:
    """Compliance rows ``A^-1 e_c`` solved in a daemon thread ahead of need (:meth:`request`), handed
    over by :meth:`take`; the owner writes them into its own arrays (the thread touches only its
    queue and its finished dict)."""

    def __init__(self, lu, local: np.ndarray):
        self._lu, self._local = lu, local
        self._n = int((local >= 0).sum())
        self._done: dict[int, np.ndarray] = {}
        self._asked: set[int] = set()
        self._lock = threading.Lock()
        self._queue: queue.Queue = queue.Queue()
        self._thread = threading.Thread(target=self._work, name="layered-row-prefetch", daemon=True)
        self._thread.start()
        _LIVE.add(self)

    def _work(self) -> None:
        while True:
            c = self._queue.get()
            if c is None:
                return
            e = np.zeros(self._n)
            e[self._local[c]] = 1.0
            col = self._lu.solve(e)
            with self._lock:
                self._done[c] = col

    def request(self, nodes: np.ndarray) -> None:
        for c in nodes.tolist():
            if c not in self._asked:
                self._asked.add(c)
                self._queue.put(c)

    def take(self, nodes: np.ndarray) -> dict[int, np.ndarray]:
        """The finished rows of ``nodes`` (removed from the store)."""
        with self._lock:
            return {c: self._done.pop(c) for c in nodes.tolist() if c in self._done}

    def close(self, wait: float = 0.0) -> None:
        """Stop the thread (after the row it is solving; waits up to ``wait`` s for it)."""
        self._queue.put(None)
        if wait > 0:
            self._thread.join(wait)


#: live prefetchers, stopped at interpreter exit (a daemon thread inside SuperLU during shutdown
#: makes the interpreter print spurious errors)
_LIVE: "weakref.WeakSet[RowPrefetcher]" = weakref.WeakSet()


@atexit.register
def _stop_prefetchers() -> None:
    for p in list(_LIVE):
        p.close(wait=2.0)


class PrefactoredContact:
    """All-node spring equilibrium with contact nodes by their reactions (module docstring).

    model: the LayeredModel; radius: m, half-width of the near set beyond the contact footprint
    (at least one lattice spacing); refresh: steps between checks of the anchors; prefetch: solve the
    compliance rows of the surface nodes around the contact in a background thread (SuperLU's
    solve releases the GIL), so a node joining the contact rarely waits for its back-solve.
    """

    def __init__(self, model, radius: float, refresh: int = REFRESH, prefetch: bool = False):
        self.model = model
        n = model.n_nodes
        self.anchor = model.fixed & np.all(model.fixed_targets == model.rest_positions, axis=1)
        self.anchor_idx = np.flatnonzero(self.anchor)
        self.anchor_targets = model.fixed_targets[self.anchor_idx].copy()
        self.free = np.flatnonzero(~self.anchor)
        self.local = np.full(n, -1, dtype=np.int64)
        self.local[self.free] = np.arange(len(self.free))
        lap = model._laplacian()
        self.lu = spla.splu(lap[self.free][:, self.free].tocsc(), permc_spec="MMD_AT_PLUS_A")
        u_anchor = self.anchor_targets - model.rest_positions[self.anchor_idx]
        self.v0 = np.ascontiguousarray(self.lu.solve(np.ascontiguousarray(
            -(lap[self.free][:, self.anchor_idx] @ u_anchor))))
        self.slot_of = np.full(n, -1, dtype=np.int64)
        self.Gt = np.zeros((16, len(self.free)))    # row k: A^-1 e_c of the node in slot k
        self.n_slots = 0
        self.near_cells = max(1, int(np.ceil(float(radius) / model.volume.spacing)))
        self.refresh = int(refresh)
        self._near_key = None
        self.near = np.zeros(0, dtype=np.int64)
        self.link_i = np.zeros(0, dtype=np.int64)   # rigid links: node, axis (its +axis neighbour is the other end)
        self.link_a = np.zeros(0, dtype=np.int64)
        self.link_force = np.zeros(0)
        self._mark = np.zeros(n, dtype=np.int64)
        self._pos_of = np.zeros(n, dtype=np.int64)
        self._near_mark = np.zeros(n, dtype=np.int64)
        self._stamp = 0
        self._steps = 0
        self._sweep_pos = 0
        self._slabs = None
        self._prefetch = RowPrefetcher(self.lu, self.local) if prefetch else None
        self.last_region = 0
        self.last_iterations = 0
        # the current solution: per axis the reacting nodes' slots and loads (eq. 1)
        self.uniq_slots = np.zeros(0, dtype=np.int64)
        self.w3 = np.zeros((3, 0))
        self.finite = True

    def __del__(self):
        if getattr(self, "_prefetch", None) is not None:
            self._prefetch.close()

    def valid(self) -> bool:
        """False once an anchor was released or moved (the factorisation no longer applies)."""
        m = self.model
        return bool(m.fixed[self.anchor_idx].all()) and np.array_equal(m.fixed_targets[self.anchor_idx],
                                                                       self.anchor_targets)

    # ------------------------------------------------------------------------------------------
    def _ensure_slots(self, nodes: np.ndarray) -> None:
        """Back-solve (once) the compliance rows of the non-anchor ``nodes`` without one."""
        new = nodes[(self.slot_of[nodes] < 0) & ~self.anchor[nodes]]
        if not len(new):
            return
        new = np.unique(new)
        need = self.n_slots + len(new)
        if need > self.Gt.shape[0]:
            grown = np.zeros((max(need, 2 * self.Gt.shape[0]), self.Gt.shape[1]))
            grown[:self.n_slots] = self.Gt[:self.n_slots]
            self.Gt = grown
        ready = self._prefetch.take(new) if self._prefetch is not None else {}
        todo = np.array([c for c in new.tolist() if c not in ready], dtype=np.int64)
        if len(todo):
            e = np.zeros((len(self.free), len(todo)))
            e[self.local[todo], np.arange(len(todo))] = 1.0
            ready.update(zip(todo.tolist(), self.lu.solve(e).T))
        for q, c in enumerate(new.tolist()):
            self.Gt[self.n_slots + q] = ready[c]
        self.slot_of[new] = np.arange(self.n_slots, need)
        self.n_slots = need

    def _near_nodes(self, contact: np.ndarray) -> np.ndarray:
        """Whole lattice columns within ``near_cells`` of the contact footprint (cached per footprint)."""
        m = self.model
        idx = m.volume.lattice_index
        ci = idx[contact]
        lo, hi = ci.min(axis=0), ci.max(axis=0)
        key = (int(lo[0]), int(lo[1]), int(hi[0]), int(hi[1]))
        if key != self._near_key:
            r = self.near_cells
            sel = ((idx[:, 0] >= lo[0] - r) & (idx[:, 0] <= hi[0] + r) & (idx[:, 1] >= lo[1] - r)
                   & (idx[:, 1] <= hi[1] + r) & ~self.anchor)
            self.near = np.flatnonzero(sel)
            self._near_key = key
        return self.near

    def _sweep_chunks(self) -> list[np.ndarray]:
        """Round-robin pieces of the free nodes: lattice slabs x = k, k + 1, cut along y into pieces of
        about ``SWEEP_CHUNK`` nodes that overlap by one y row; together they hold both ends of every
        spring, so a sweep over them writes every node and checks every spring once."""
        idx = self.model.volume.lattice_index[self.free]
        ix, iy = idx[:, 0] - idx[:, 0].min(), idx[:, 1] - idx[:, 1].min()
        chunks = []
        for k in range(max(1, int(ix.max()))):
            pair = np.flatnonzero((ix == k) | (ix == k + 1))
            ys = iy[pair]
            pieces = max(1, int(round(len(pair) / SWEEP_CHUNK)))
            bounds = np.linspace(ys.min(), ys.max() + 1, pieces + 1).round().astype(int)
            for lo, hi in zip(bounds[:-1], bounds[1:]):
                sel = pair[(ys >= lo) & (ys <= hi)]   # hi inclusive: the overlap row
                if len(sel):
                    chunks.append(self.free[sel])
        return chunks

    def _sweep_chunk(self) -> np.ndarray:
        """The next round-robin piece (:meth:`_sweep_chunks`)."""
        if self._slabs is None:
            self._slabs = self._sweep_chunks()
        k = self._sweep_pos
        self._sweep_pos = (k + 1) % len(self._slabs)
        return self._slabs[k]

    # ------------------------------------------------------------------------------------------
    def solve(self, contact: np.ndarray, full: bool | None = None) -> tuple[np.ndarray, bool]:
        """Equilibrium with the Dirichlet nodes ``contact`` (non-anchor) at their targets: writes the
        near set and the next chunk of the round-robin sweep (every free node if ``full``), the rigid links
        and their pushes; returns (nodes written, settled). The model's other positions are then
        stale until :meth:`materialise` (the model calls it when they are read)."""
        m = self.model
        rest = m.rest_positions
        self._steps += 1
        contact = np.asarray(contact, dtype=np.int64)
        if full:
            nodes = self.free
        else:
            # no contact: the previous near set goes back to the anchors' response, the rest lazily
            near = self._near_nodes(contact) if len(contact) else self.near
            nodes = np.concatenate([near, self._sweep_chunk()])
        self._stamp += 1
        stamp = self._stamp
        nm = self._near_mark
        nm[nodes] = stamp
        nm[contact] = stamp
        t_c = m.fixed_targets[contact] - rest[contact]
        li, la = self.link_i, self.link_a
        settled = False
        it = 0
        for it in range(MAX_ACTIVE_SET_ITERS):
            lj = m.nbr[li, 2 * la + 1].astype(np.int64)
            self._ensure_slots(contact)
            if len(li):
                self._ensure_slots(li)
                self._ensure_slots(lj)
            self._stamp += 1
            uniq = pk.unique_reacting(contact, li, lj, self.anchor, self._mark, self._stamp, self._pos_of)
            w = np.zeros((3, len(uniq)))
            lam = np.zeros(len(li))
            s0 = rest[lj, la] - rest[li, la] - m.lmin[li, 2 * la + 1]
            viol, finite = pk.solve_step(contact, t_c, li, la, s0, uniq, self._pos_of, self.anchor, self.local,
                                         self.slot_of, self.Gt, self.v0, m.nbr, m.lmin, nodes, rest, m.fixed,
                                         m.fixed_targets, m._x, m._xstamp, m._xversion, nm, stamp, LINK_TOL, w, lam)
            keep = lam > 0.0
            if keep.all() and not len(viol):
                settled = True
                break
            # released links (in tension) go, springs past their extreme length join (warm start)
            key = np.unique(np.concatenate([li[keep] * 3 + la[keep], viol[:, 0] * 3 + viol[:, 1]]))
            li, la = key // 3, key % 3
        self.last_iterations = it + 1
        # the pushes of the previous links and of the written nodes go; the settled links' reactions
        # are the new pushes (eq. 2.5)
        m.push[nodes] = 0.0
        if len(self.link_i):
            m.push[self.link_i] = 0.0
            m.push[m.nbr[self.link_i, 2 * self.link_a + 1]] = 0.0
        if not settled:
            li, la, lam = li[:0], la[:0], lam[:0]
        if len(li):
            lj = m.nbr[li, 2 * la + 1].astype(np.int64)
            f = np.maximum(lam, 0.0)
            m.push[li, 2 * la + 1] = f
            m.push[lj, 2 * la] = f
        self.link_i, self.link_a, self.link_force = li, la, lam
        self.uniq_slots = self.slot_of[uniq]
        self.w3 = w
        self.finite = bool(finite)
        self.last_region = len(nodes)
        if self._prefetch is not None and len(contact):   # the surface around the contact may join next
            ring = self.near[(m.nbr[self.near, 5] < 0) & (self.slot_of[self.near] < 0)]
            if len(ring):   # nearest to the contact first
                d = np.linalg.norm(rest[ring] - rest[contact].mean(axis=0), axis=1)
                self._prefetch.request(ring[np.argsort(d)])
        return nodes, settled

    @property
    def links(self) -> list[np.ndarray]:
        """Per axis, the (L,2) node pairs (i below j) held as rigid links."""
        out = []
        for a in range(3):
            i = self.link_i[self.link_a == a]
            out.append(np.stack([i, self.model.nbr[i, 2 * a + 1].astype(np.int64)], axis=1))
        return out

    def positions_of(self, nodes: np.ndarray) -> np.ndarray:
        """(K,3) m current positions of ``nodes`` from the solution (nothing written)."""
        m = self.model
        out = np.empty((len(nodes), 3))
        pk.rows_positions(np.asarray(nodes, dtype=np.int64), self.local, self.uniq_slots, self.w3, self.Gt,
                          self.v0, m.rest_positions, m.fixed, m.fixed_targets, out)
        return out

    def materialise(self) -> None:
        """Write every free node's position from the current solution."""
        m = self.model
        ok = pk.write_rows(self.free, self.local, self.uniq_slots, self.w3, self.Gt, self.v0, m.rest_positions,
                           m.fixed, m.fixed_targets, m._x, m._xstamp, m._xversion)
        self.finite = self.finite and bool(ok)


__all__ = ["PrefactoredContact", "REFRESH", "LINK_TOL"]
