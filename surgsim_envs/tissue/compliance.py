"""Condensed compliance of a linear elastic body: a sparse factorisation of the stiffness on the
free dofs, and compliance columns of the nodes that are loaded, computed on first use and cached.

The precomputed-compliance idea of SOFA's ``PrecomputedConstraintCorrection`` /
``LinearSolverConstraintCorrection``: for a linear body ``K u = f`` with Dirichlet dofs removed,
the displacement caused by forces on a few nodes A is ``u = C_A f_A`` where the columns
``C_A = K_ff^-1 P_A^T`` (3N x 3|A|) come from back-substitutions of one factorisation. A contact
problem then only needs the small block ``W_AA = P_A C_A`` (m/N), and the full displacement is
one (3N x 3|A|) product instead of a sparse solve. Columns are kept up to a memory budget and
evicted least recently used.

The factorisation is SuperLU (scipy, always there) by default. ``solver="pardiso"`` uses MKL
PARDISO's sparse Cholesky (the optional ``pypardiso`` package) instead: K is symmetric positive
definite on the free dofs, and on a 20,000-dof ANP stiffness of a graded slab it factorised 7x and
back-substituted 6x faster than SuperLU here (1.3 s against 9.7 s; 300 right-hand sides in 2.9 s
against 17.9 s; the solutions agree to 3e-15). ``"auto"`` takes it when it is installed.

Units: stiffness N/m, compliance m/N, displacements m, forces N. numpy/scipy + numba only
(``pypardiso`` optional).
"""

from __future__ import annotations

import os
import warnings

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError

#: default memory for cached compliance columns (MB); each node costs 72 x n_nodes bytes
DEFAULT_CACHE_MB = 256.0
#: free dofs above which a SuperLU factorisation warns that it takes minutes (and names PARDISO)
SLOW_SUPERLU_DOFS = 30_000
#: the sparse factorisations :class:`CondensedCompliance` accepts ("auto": pardiso when installed)
SOLVERS = ("superlu", "pardiso", "auto")


def pardiso_available() -> bool:
    """Whether the optional ``pypardiso`` package (MKL PARDISO) can be imported."""
    try:
        import_pypardiso()
    except ImportError:
        return False
    return True


def import_pypardiso():
    """The ``pypardiso`` module (ImportError without it), MKL's runtime named for it first: without
    ``PYPARDISO_MKL_RT`` each pypardiso solver (one is made on import) searches the environment's
    whole lib tree for the library (1.4 s each here); the mkl wheel's file list names it at once."""
    if "PYPARDISO_MKL_RT" not in os.environ:
        path = mkl_runtime_path()
        if path is not None:
            os.environ["PYPARDISO_MKL_RT"] = path
    import pypardiso

    return pypardiso


def mkl_runtime_path() -> str | None:
    """The path of MKL's runtime library (``mkl_rt``) from the installed ``mkl`` distribution's file
    list (the shortest name first, as pypardiso's own search), or None."""
    from importlib import metadata

    try:
        files = metadata.files("mkl") or []
    except metadata.PackageNotFoundError:
        return None
    for f in sorted((f for f in files if "mkl_rt" in f.name), key=lambda f: len(str(f))):
        path = str(f.locate())
        if os.path.exists(path):
            return path
    return None


class _Pardiso:
    """MKL PARDISO's Cholesky of a symmetric positive definite matrix, with SuperLU's ``solve``."""

    def __init__(self, kff):
        pypardiso = import_pypardiso()
        self.matrix = sp.triu(kff, format="csr")
        self.matrix.sort_indices()
        self.solver = pypardiso.PyPardisoSolver(mtype=2)        # real symmetric positive definite
        self.solver.factorize(self.matrix)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self.solver.solve(self.matrix, rhs)

    def __del__(self):
        try:
            self.solver.free_memory(everything=True)
        except Exception:       # interpreter shutdown: MKL may be gone already
            pass


@njit(cache=True, nogil=True)
def gather_block(cols, slots, nodes, out):
    """``out`` (3m,3m) = W_AA: rows = dofs of ``nodes``, columns = their cached ``cols[slots]``
    ((capacity, 3, 3N) compliance columns, m/N: ``cols[s, j]`` is the response to a unit force along
    axis j on the node of slot s)."""
    m = nodes.shape[0]
    for b in range(m):
        s = slots[b]
        for a in range(m):
            r = 3 * nodes[a]
            for i in range(3):
                for j in range(3):
                    out[3 * a + i, 3 * b + j] = cols[s, j, r + i]


@njit(cache=True, nogil=True)
def scaled_block(cols, slots, nodes, c):
    """W_AA / c (3m,3m) of ``nodes`` from their cached columns (:func:`gather_block`); ``c`` the
    hereditary step's factor (1: elastic)."""
    n3 = 3 * nodes.shape[0]
    w = np.empty((n3, n3))
    gather_block(cols, slots, nodes, w)
    if c != 1.0:
        for i in range(n3):
            for j in range(n3):
                w[i, j] = w[i, j] / c
    return w


@njit(cache=True, nogil=True)
def respond(cols, slots, nodes, g, c, u0, u, applied):
    """u (3N,) = u0 + C_A g / c for the forces ``g`` (3m,) N on ``nodes`` (their cached columns),
    and ``applied[nodes]`` = g."""
    m = nodes.shape[0]
    for d in range(u.shape[0]):
        u[d] = u0[d]
    gs = np.empty((m, 3))
    for b in range(m):
        for j in range(3):
            gs[b, j] = g[3 * b + j] / c if c != 1.0 else g[3 * b + j]
            applied[nodes[b], j] = g[3 * b + j]
    add_response(cols, slots, gs, u)


@njit(cache=True, nogil=True)
def add_response(cols, slots, g, out):
    """``out`` (3N,) += sum_b cols[slots[b]] @ g[b] (m): the displacement of nodal forces g (m,3) N."""
    n3 = out.shape[0]
    for b in range(slots.shape[0]):
        s = slots[b]
        g0, g1, g2 = g[b, 0], g[b, 1], g[b, 2]
        if g0 == 0.0 and g1 == 0.0 and g2 == 0.0:
            continue
        c0, c1, c2 = cols[s, 0], cols[s, 1], cols[s, 2]     # each axis' column contiguous: the loop vectorises
        for d in range(n3):
            out[d] += c0[d] * g0 + c1[d] * g1 + c2[d] * g2


@njit(cache=True, nogil=True)
def gather_axis_block(cols, slots, nodes, axis, out):
    """``out`` (m,m) = the ``axis`` rows of the dofs of ``nodes`` in their cached single-axis columns
    ``cols[slots]`` ((capacity, 3N), m/N)."""
    m = nodes.shape[0]
    for b in range(m):
        s = slots[b]
        for a in range(m):
            out[a, b] = cols[s, 3 * nodes[a] + axis]


@njit(cache=True, nogil=True)
def add_axis_response(cols, slots, g, out):
    """``out`` (3N,) += sum_b cols[slots[b]] g[b] (m): the displacement of forces g (m,) N along one axis."""
    n3 = out.shape[0]
    for b in range(slots.shape[0]):
        s = slots[b]
        gb = g[b]
        if gb == 0.0:
            continue
        for d in range(n3):
            out[d] += cols[s, d] * gb


@njit(cache=True, nogil=True)
def cached_slots(slot_of, last_used, nodes, tick, out):
    """``out`` = the cache slots of ``nodes`` and their ``last_used`` set to ``tick``, if every node has
    one; returns False (nothing written) when a column is missing."""
    for k in range(nodes.shape[0]):
        if slot_of[nodes[k]] < 0:
            return False
    for k in range(nodes.shape[0]):
        s = slot_of[nodes[k]]
        out[k] = s
        last_used[s] = tick
    return True


def free_slots(slot_of: np.ndarray, node_in: np.ndarray, last_used: np.ndarray, nodes: np.ndarray,
               count: int) -> np.ndarray:
    """``count`` empty cache slots, evicting the least recently used columns (never those of ``nodes``)
    where too few are empty; ``slot_of`` (node -> slot) and ``node_in`` (slot -> node) are updated
    for the evicted ones."""
    empty = np.flatnonzero(node_in < 0)
    if len(empty) < count:
        busy = slot_of[nodes]
        busy = busy[busy >= 0]
        order = np.argsort(last_used, kind="stable")
        order = order[~np.isin(order, busy) & (node_in[order] >= 0)]
        drop = order[:count - len(empty)]
        slot_of[node_in[drop]] = -1
        node_in[drop] = -1
        empty = np.flatnonzero(node_in < 0)
    return empty[:count]


class AxisColumns:
    """Cached single-axis compliance columns (the response to a unit force along ``axis`` on one node),
    least recently used evicted beyond ``capacity`` nodes: a load along one axis only (a frictionless
    press) needs a third of the back-substitutions of :meth:`CondensedCompliance.slots`."""

    def __init__(self, n_nodes: int, axis: int, capacity: int):
        self.axis = int(axis)
        self.capacity = int(capacity)
        self.cols = np.zeros((self.capacity, 3 * n_nodes))     # zero pages mapped lazily, as the 3-column cache
        self.slot_of = -np.ones(n_nodes, dtype=np.int64)
        self.node_in = -np.ones(self.capacity, dtype=np.int64)
        self.last_used = np.zeros(self.capacity, dtype=np.int64)
        self.tick = 0


class CondensedCompliance:
    """Factorised stiffness ``K`` (3N x 3N, N/m, dof = 3 node + axis) on the dofs where ``free``
    ((3N,) bool) is True, with lazily cached compliance columns of loaded nodes.

    cache_mb: memory for cached columns (MB); the least recently used are evicted beyond it.
    solver: the factorisation, one of :data:`SOLVERS` (module docstring).
    """

    def __init__(self, stiffness: sp.spmatrix, free: np.ndarray, *, cache_mb: float = DEFAULT_CACHE_MB,
                 solver: str = "superlu"):
        k = sp.csr_matrix(stiffness)
        n3 = k.shape[0]
        free = np.asarray(free, dtype=bool).reshape(-1)
        if k.shape != (n3, n3) or n3 % 3 or free.shape != (n3,):
            raise ConfigError(f"condensed compliance needs a square 3N x 3N stiffness and a (3N,) free mask, got "
                              f"{k.shape} and {free.shape}")
        if not free.any():
            raise ConfigError("condensed compliance: every dof is fixed; nothing can move")
        validate.positive(cache_mb, "cache_mb", unit="MB", fix="the memory of cached compliance rows, e.g. 256")
        self.n_nodes = n3 // 3
        self.free = free
        self.free_index = np.flatnonzero(free)
        kff = k[free][:, free].tocsc()
        solver = validate.choice(solver, "condensed compliance: solver", SOLVERS,
                                 fix="'superlu' (scipy), 'pardiso' (needs pypardiso) or 'auto'")
        if solver == "pardiso" and not pardiso_available():
            raise ConfigError("condensed compliance: solver='pardiso' needs the optional package pypardiso "
                              "(pip install pypardiso); or use solver='auto' (SuperLU without it)")
        if solver == "auto":
            solver = "pardiso" if pardiso_available() else "superlu"
        self.solver = solver
        if solver == "pardiso":
            self.lu = _Pardiso(kff)
            if not np.all(np.isfinite(self.lu.solve(np.ones(kff.shape[0])))):
                raise ConfigError("condensed compliance: the stiffness on the free dofs is singular; fix enough "
                                  "nodes to hold the body (a fixed base)")
        else:
            self._superlu(kff)
        self.capacity = max(1, min(self.n_nodes, int(cache_mb * 1e6 // (72.0 * self.n_nodes))))
        # the whole budget at once: np.zeros maps zero pages lazily, so memory is touched only as columns
        # are written, and no growth copies the cached columns (a re-factorisation per episode, as a
        # task's per-episode lump makes, paid that copy again every episode)
        self.cols = np.zeros((self.capacity, 3, n3))      # (slot, force axis, dof)
        self.slot_of = -np.ones(self.n_nodes, dtype=np.int64)
        self.node_in = -np.ones(self.capacity, dtype=np.int64)
        self.last_used = np.zeros(self.capacity, dtype=np.int64)
        self.tick = 0
        self.columns_computed = 0
        self._axes: dict[int, AxisColumns] = {}        # single-axis column caches, made on first use

    def _superlu(self, kff) -> None:
        if kff.shape[0] > SLOW_SUPERLU_DOFS:
            warnings.warn(f"condensed compliance: factorising {kff.shape[0]:,} free dofs with SuperLU takes minutes (a "
                          "layered wall's averaged-pressure stiffness: 58 s at 32,175 dofs, 210 s at 61,008 on a 2-core "
                          "host); the optional MKL PARDISO took 2.9 s and 7.8 s: pip install pypardiso and use "
                          "solver='auto' or 'pardiso'", stacklevel=3)
        try:   # K is symmetric: a symmetric ordering keeps the fill of the ANP matrix lower (measured 2x faster)
            self.lu = spla.splu(kff, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
        except RuntimeError as exc:
            raise ConfigError(f"condensed compliance: the stiffness on the free dofs is singular ({exc}); fix "
                              "enough nodes to hold the body (a fixed base)") from None

    # ------------------------------------------------------------------------------------------
    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Full solve: displacement (3N,) or (3N,k) m for forces ``rhs`` (3N,) or (3N,k) N (zero on fixed dofs)."""
        rhs = np.asarray(rhs, dtype=np.float64)
        out = np.zeros(rhs.shape)
        sol = self.lu.solve(np.ascontiguousarray(rhs[self.free_index]))
        if not np.all(np.isfinite(sol)):
            raise ConfigError("condensed compliance: the factorised stiffness gave a non-finite solution (singular)")
        out[self.free_index] = sol
        return out

    def slots(self, nodes: np.ndarray) -> np.ndarray:
        """Cache slots of ``nodes`` ((m,) int), computing missing columns in one multi-rhs solve."""
        nodes = np.asarray(nodes, dtype=np.int64)
        self.tick += 1
        if len(nodes) > self.capacity:
            raise ConfigError(f"condensed compliance: {len(nodes)} loaded nodes exceed the column cache "
                              f"({self.capacity} nodes); raise cache_mb")
        s = np.empty(len(nodes), dtype=np.int64)
        if cached_slots(self.slot_of, self.last_used, nodes, self.tick, s):    # every column cached: no solve
            return s
        missing = nodes[self.slot_of[nodes] < 0]
        if len(missing):
            use = free_slots(self.slot_of, self.node_in, self.last_used, nodes, len(missing))
            rhs = np.zeros((3 * self.n_nodes, 3 * len(missing)))
            for j in range(3):
                rhs[3 * missing + j, 3 * np.arange(len(missing)) + j] = 1.0
            sol = self.solve(rhs)                          # (3N, 3m): response to unit forces
            self.cols[use] = sol.reshape(3 * self.n_nodes, len(missing), 3).transpose(1, 2, 0)
            self.node_in[use] = missing
            self.slot_of[missing] = use
            self.columns_computed += len(missing)
        s = self.slot_of[nodes]
        self.last_used[s] = self.tick
        return s

    def _axis_cache(self, axis: int) -> AxisColumns:
        axis = validate.integer(axis, "condensed compliance: axis", lo=0, hi=2, fix="0, 1 or 2 (2 = z)")
        cache = self._axes.get(axis)
        if cache is None:
            cache = self._axes[axis] = AxisColumns(self.n_nodes, axis, 3 * self.capacity)
        return cache

    def axis_slots(self, nodes: np.ndarray, axis: int) -> np.ndarray:
        """Slots of ``nodes`` ((m,) int) in the single-axis column cache of ``axis``, computing the missing
        columns in one multi-rhs solve."""
        nodes = np.asarray(nodes, dtype=np.int64)
        c = self._axis_cache(axis)
        c.tick += 1
        if len(nodes) > c.capacity:
            raise ConfigError(f"condensed compliance: {len(nodes)} loaded nodes exceed the axis column cache "
                              f"({c.capacity} nodes); raise cache_mb")
        missing = nodes[c.slot_of[nodes] < 0]
        if len(missing):
            use = free_slots(c.slot_of, c.node_in, c.last_used, nodes, len(missing))
            rhs = np.zeros((3 * self.n_nodes, len(missing)))
            rhs[3 * missing + c.axis, np.arange(len(missing))] = 1.0
            c.cols[use] = self.solve(rhs).T                   # (m, 3N): response to unit forces along the axis
            c.node_in[use] = missing
            c.slot_of[missing] = use
            self.columns_computed += len(missing)
        s = c.slot_of[nodes]
        c.last_used[s] = c.tick
        return s

    def axis_block(self, nodes: np.ndarray, axis: int, slots: np.ndarray | None = None) -> np.ndarray:
        """W (m,m) m/N: displacement along ``axis`` of ``nodes`` per unit force along it on them."""
        nodes = np.asarray(nodes, dtype=np.int64)
        s = self.axis_slots(nodes, axis) if slots is None else slots
        out = np.empty((len(nodes), len(nodes)))
        gather_axis_block(self._axis_cache(axis).cols, s, nodes, int(axis), out)
        return out

    def axis_response(self, slots: np.ndarray, forces: np.ndarray, axis: int, out: np.ndarray) -> np.ndarray:
        """``out`` (3N,) += displacement (m) of ``forces`` (m,) N along ``axis`` on the nodes at ``slots``."""
        add_axis_response(self._axis_cache(axis).cols, np.asarray(slots, dtype=np.int64),
                          np.ascontiguousarray(forces, dtype=np.float64), out)
        return out

    def block(self, nodes: np.ndarray, slots: np.ndarray | None = None) -> np.ndarray:
        """W_AA (3m,3m) m/N: displacement of the dofs of ``nodes`` per unit force on them."""
        nodes = np.asarray(nodes, dtype=np.int64)
        s = self.slots(nodes) if slots is None else slots
        out = np.empty((3 * len(nodes), 3 * len(nodes)))
        gather_block(self.cols, s, nodes, out)
        return out

    def response(self, slots: np.ndarray, forces: np.ndarray, out: np.ndarray) -> np.ndarray:
        """``out`` (3N,) += displacement (m) of ``forces`` (m,3) N on the nodes cached at ``slots``."""
        add_response(self.cols, np.asarray(slots, dtype=np.int64), np.ascontiguousarray(forces, dtype=np.float64), out)
        return out
