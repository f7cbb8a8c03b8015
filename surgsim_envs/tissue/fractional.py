"""Variable-order fractional viscoelastic tissue on tetrahedra (the variable-order paper, extended to 3-D).

The variable-order paper writes the stress as a fractional derivative of the elastic response (2-D: eqs. 11-13,
``sigma = D^q(t) [C eps]`` with C the isotropic elasticity written with alpha, beta, gamma).
In 3-D, per linear tet, with C Hooke's tensor of the element's (young, poisson)::

    sigma = (1 - g) C eps  +  g tau^q D^q(t) [C eps]            (RL derivative, order q(t))

* g = ``relax_fraction`` (material field, per element): the part of the stiffness carried by the
  fractional branch. ``branch_fraction=1.0`` gives the paper's law alone (no parallel spring).
  For g < 1 the spring (1 - g) C holds the long-time equilibrium (a fractional Kelvin-Voigt solid).
* tau = ``relax_time`` (s, per element): time scale of the branch (1-D: eta = g E tau^q), so a
  branch of order q has modulus g E at t = tau after a strain step (the unit-free choice).
* q(t) in [0, 1): a number or a :class:`~surgsim_envs.tissue.fractional_calculus.PiecewiseOrder`
  (``order=``; default ``material.extra["fractional_order"]`` or 0.3). q = 0 is linear elastic
  (young), q -> 1 adds a Newtonian viscosity g E tau.

Discretisation: linear tets, small strain (``K_e = B^T D B V``); Grunwald-Letnikov in time with
the short-memory principle: ``D^q y(t_n) ~ dt^-q sum_{k=0}^{L} w_k y_{n-k}`` (L = ``memory``
steps, default 100) plus, by default, block averages of the older states out to 10,000 steps. The history is the nodal displacement d = x - X of the last L steps
(a ring buffer, L x 3N numbers): because the element strain is linear in d (eps_e = B_e d_e),
the weighted sum of the element strain histories equals the strain of the weighted sum of
displacements, so ``sum_e B_e^T V_e C_e sum_k w_k eps_e,n-k = K_f sum_k w_k d_{n-k}`` exactly:
keeping the history per node is the per-element strain history, in 3N instead of 6T numbers per
step (1,000-node box: 3,000 vs 26,244). A second ring keeps block averages of older states
(two-level memory, ``coarse_blocks``/``coarse_step``; by default it spans 10,000 steps, every
task's longest episode: plain truncation at 100 steps stalls creep and relaxation after 0.1 s). Nodal forces::

    f = f_ext + m g_grav - K_inf d_n - dt^-q K_f s_n,   s_n = sum_{k=0}^{L} w_k^{(q_n)} d_{n-k}
    K_inf = sum_e (1 - g_e) K_e,   K_f = sum_e g_e tau_e^q K_e

Integrators: ``"symplectic"`` (semi-implicit Euler, mass damping implicit, one numba call per
step; stable while ``dt < critical_dt()``), ``"implicit"`` (backward Euler with the current-step
term w_0 d_{n+1} implicit: one sparse LU factorisation of ``M (1 + alpha dt) + dt^2 (K_inf +
dt^-q K_f)`` per (dt, q, fixed set), one back-substitution per step; stable at any dt), and
``"auto"`` (default; the base-class rule between the two).

Units: m, s, kg, N, Pa. See docs/models/fractional.md.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from surgsim_envs.errors import ConfigError
from surgsim_envs.tissue import fem_assembly as asm
from surgsim_envs.tissue import fractional_calculus as fc
from surgsim_envs.tissue import fractional_kernels as kern
from surgsim_envs.tissue.base import TissueModel
from surgsim_envs.tissue.fem_kernels import count_inverted

DEFAULT_ORDER = 0.3
DEFAULT_MEMORY = 100
#: steps of history the default two-level memory spans (fine window + block averages): at least
#: every task's longest episode in physics steps (Palpation-v0 6 s at 1 ms = 6,000; Grasp-v0 and
#: Slippage-v0 3 s at 0.4 ms = 7,500), so no task's creep or relaxation stalls at L dt
DEFAULT_SPAN_STEPS = 10_000
#: the history ring may not exceed this many bytes (2 (L + 1) x 3N doubles)
MAX_HISTORY_BYTES = 2 * 1024 ** 3


class FractionalTetModel(TissueModel):
    """Fractional (variable-order) viscoelastic linear tets; see the module docstring.

    Parameters (besides those of :class:`TissueModel`)
    ----------
    order: q in [0, 1): a number or a PiecewiseOrder of simulated time (s).
    memory: short-memory length L (steps of history kept in full), >= 1. With plain truncation
        (``coarse_blocks=0``) the model remembers L dt seconds: beyond that relaxation and creep
        stall (the truncated branch acts as a spring); the cost per step grows linearly with L
        (docs/models/fractional.md). Default 100, with the two-level memory below spanning
        DEFAULT_SPAN_STEPS.
    coarse_blocks, coarse_step: two-level memory: beyond the L-step window keep ``coarse_blocks``
        averages of ``coarse_step`` (<= L, default L // 2) end states each, weighted by the exact sum
        of their lags' GL weights; spans L + coarse_blocks x coarse_step steps for L + coarse_blocks
        rows of work (default: enough blocks to span DEFAULT_SPAN_STEPS; 0 gives plain truncation).
    branch_fraction: None (use the material's ``relax_fraction`` per element) or a number in
        [0, 1] for every element; 1.0 = the paper's law alone.
    """

    name = "fractional"
    summary = "Variable-order fractional viscoelastic tets (the variable-order paper): sigma = (1-g) C eps + g tau^q D^q(t) C eps, short memory"
    integrators = ("symplectic", "implicit")
    auto_pair = ("symplectic", "implicit")
    default_integrator = "auto"
    capabilities: ClassVar[frozenset] = frozenset({"forces", "unstructured_mesh", "history", "viscoelastic", "static_solve",
                                                   "subsurface_stiffness"})
    material_fields = ("young", "poisson", "density", "damping", "relax_fraction", "relax_time")
    node_field_names = ("displacement", "stress", "order")

    def __init__(self, volume, material="liver", *, integrator=None, order=None, memory: int = DEFAULT_MEMORY,
                 coarse_blocks: int | None = None, coarse_step: int | None = None,
                 branch_fraction: float | None = None, **base_kwargs):
        if not (isinstance(memory, (int, np.integer)) and not isinstance(memory, bool) and memory >= 1):
            raise ConfigError(f"memory (short-memory length L in steps) must be an integer >= 1, got {memory!r}")
        self.memory = int(memory)
        if coarse_step is None:
            coarse_step = max(1, self.memory // 2)
        if coarse_blocks is None and isinstance(coarse_step, (int, np.integer)) and coarse_step >= 1:
            coarse_blocks = max(0, -(-(DEFAULT_SPAN_STEPS - self.memory) // int(coarse_step)))
        if not (isinstance(coarse_blocks, (int, np.integer)) and not isinstance(coarse_blocks, bool) and coarse_blocks >= 0):
            raise ConfigError(f"coarse_blocks (block averages kept beyond the memory) must be an integer >= 0, got {coarse_blocks!r}")
        if not (isinstance(coarse_step, (int, np.integer)) and 1 <= coarse_step <= self.memory):
            raise ConfigError(f"coarse_step (steps per block average) must be an integer in [1, memory={self.memory}], "
                              f"got {coarse_step!r}")
        self.coarse_blocks, self.coarse_step = int(coarse_blocks), int(coarse_step)
        self._branch_override = branch_fraction
        if branch_fraction is not None and not (isinstance(branch_fraction, (int, float)) and 0.0 <= branch_fraction <= 1.0):
            raise ConfigError(f"branch_fraction must be None (material relax_fraction) or a number in [0, 1], got {branch_fraction!r}")
        ring = 2 * (self.memory + 1 + self.coarse_blocks) * 3 * volume.n_nodes * 8
        if ring > MAX_HISTORY_BYTES:
            raise ConfigError(f"memory={memory} steps + coarse_blocks={self.coarse_blocks} on {volume.n_nodes} nodes "
                              f"needs a {ring / 1024 ** 3:.1f} GB history ring (limit {MAX_HISTORY_BYTES / 1024 ** 3:.0f} "
                              "GB); use a shorter memory, fewer coarse blocks or a coarser mesh")
        super().__init__(volume, material, integrator=integrator, **base_kwargs)
        if order is None:
            order = self.material.extra.get("fractional_order", DEFAULT_ORDER)
        self.order = order if isinstance(order, fc.PiecewiseOrder) else fc.PiecewiseOrder((), (fc.check_order(order),))
        if max(self.order.values) >= 1.0:
            raise ConfigError(f"order q must be < 1 for the tissue model (q = 1 is a pure viscous fluid), got {self.order.values}")
        if branch_fraction is not None:
            self.fields["relax_fraction"] = np.full(len(self.volume.tets), float(branch_fraction))
            self._fields0["relax_fraction"] = self.fields["relax_fraction"].copy()
        self._setup()

    # ------------------------------------------------------------------------------------------
    # set-up and material fields
    def _setup(self) -> None:
        vol = self.volume
        n = vol.n_nodes
        self.tets = np.ascontiguousarray(vol.tets, dtype=np.int64)
        self.grads, self.tet_volume, _ = asm.shape_gradients(self.rest_positions, self.tets)
        self._b = asm.b_matrices(self.grads)
        rows = np.repeat(self.tets, 4, axis=1).ravel()        # node pairs (a, b) of every tet, a-major
        cols = np.tile(self.tets, (1, 4)).ravel()
        self._indptr, self._indices, self._slot = kern.csr_pattern(rows, cols, n)
        self._rest_flat = self.rest_positions.reshape(-1).copy()
        # ring of the displacement at the end of each of the last L + 1 steps, newest first
        self._buf = np.zeros((2 * (self.memory + 1), 3 * n))
        self._pos = self.memory + 1
        self._count = 0
        self._work = [np.zeros(3 * n) for _ in range(3)]
        # two-level memory: block averages of coarse_step end states beyond the fine window
        self._cbuf = np.zeros((2 * max(self.coarse_blocks, 1), 3 * n))
        self._csum = np.zeros(3 * n)
        self._remote = np.zeros(3 * n)
        self._clear_coarse()
        self._s_last = np.zeros(3 * n)
        self._c_last = 0.0
        self._weights: dict[float, np.ndarray] = {}
        self._q_assembled = None
        self._lu = None
        self._crit = None
        self.integrated_external_forces = np.zeros((n, 3))
        self._build_material()

    def _build_material(self) -> None:
        """Element stiffness, the K_el / K_inf data, masses and damping from the current fields."""
        young, poisson = self.fields["young"], self.fields["poisson"]
        bad = np.flatnonzero((young <= 0) | (poisson >= 0.5) | (poisson <= -1))
        if len(bad):
            raise ConfigError(f"fractional model needs E > 0 and -1 < nu < 0.5; element {bad[0]} has "
                              f"E={young[bad[0]]!r} Pa, nu={poisson[bad[0]]!r}")
        g = self.fields["relax_fraction"]
        if np.any((g < 0) | (g > 1)) or np.any(self.fields["relax_time"] <= 0):
            raise ConfigError("relax_fraction must lie in [0, 1] and relax_time > 0 s in every element")
        ke = asm.element_stiffness(self._b, asm.d_matrices(young, poisson), self.tet_volume)
        # (T, 12, 12) -> node blocks (T, a, b, 3, 3) -> (T*16, 9), matching the (a, b) pair order of _slot
        self._ke = ke.reshape(-1, 4, 3, 4, 3).transpose(0, 1, 3, 2, 4).reshape(len(self.tets), 16, 9)
        self._a_el = self._scatter(np.ones(len(self.tets)))
        self._a_inf = self._scatter(1.0 - g)
        self.masses = self._lumped_masses()
        self._inv_m = 1.0 / self.masses
        md = np.zeros(len(self.rest_positions))
        np.add.at(md, self.tets.ravel(), np.repeat(self.fields["density"] * self.tet_volume / 4.0 * self.fields["damping"], 4))
        self._alpha_node = md / self.masses
        self._q_assembled = None
        self._lu = None
        self._crit = None

    def _scatter(self, coef: np.ndarray) -> np.ndarray:
        """(B, 9) block data of sum_e coef_e K_e on the shared node-block pattern."""
        vals = (coef[:, None, None] * self._ke).reshape(-1, 9)
        nb = len(self._indices)
        return np.ascontiguousarray(np.stack([np.bincount(self._slot, weights=vals[:, k], minlength=nb)
                                              for k in range(9)], axis=1))

    def _branch(self, q: float) -> np.ndarray:
        """CSR data of K_f = sum_e g_e tau_e^q K_e (re-assembled when q changes)."""
        if self._q_assembled != q:
            self._a_f = self._scatter(self.fields["relax_fraction"] * self.fields["relax_time"] ** q)
            self._q_assembled = q
        return self._a_f

    def _gl(self, q: float) -> np.ndarray:
        """GL weights w_0..w_Lmax (Lmax = L, or beyond it over the coarse blocks) and, with coarse
        blocks, their cumulative sums."""
        w = self._weights.get(q)
        if w is None:
            lmax = self.memory + (self.coarse_blocks + 2) * self.coarse_step if self.coarse_blocks else self.memory
            w = self._weights[q] = fc.gl_weights(q, lmax)
            self._cumw = getattr(self, "_cumw", {})
            self._cumw[q] = np.concatenate([[0.0], np.cumsum(w)])
        return w

    def _clear_coarse(self) -> None:
        self._cpos = max(self.coarse_blocks, 1)
        self._ccount = 0
        self._csum[:] = 0.0
        self._cn = 0
        self._pushes = 0
        self._remote[:] = 0.0

    def _remote_sum(self, q: float, shift: int) -> np.ndarray:
        """sum over the end states older than the fine window (lag > L) of w_lag d, each coarse block
        contributing its average times the summed weights of its lags beyond L (shift 0: the
        symplectic lags P - 1 - e, shift 1: the implicit ones P - e; e the end-state index)."""
        out = self._remote
        if not self._ccount:
            out[:] = 0.0
            return out
        m, p, fine = self.coarse_step, self._pushes, self.memory
        cum = self._cumw[q]
        b = p // m - 1 - np.arange(self._ccount)               # block index of ring entries, newest first
        lag_hi = p - 1 - b * m + shift                          # oldest state of the block
        lag_lo = lag_hi - (m - 1)
        a = np.maximum(lag_lo, fine + 1)
        wts = np.where(a <= lag_hi, cum[np.minimum(lag_hi, len(cum) - 2) + 1] - cum[np.minimum(a, len(cum) - 1)], 0.0)
        kern.history_sum(self._cbuf, self._cpos, self._ccount, np.ascontiguousarray(wts), out)
        return out

    def _push_coarse(self, d: np.ndarray) -> None:
        self._pushes += 1
        if not self.coarse_blocks:
            return
        self._csum += d
        self._cn += 1
        if self._cn == self.coarse_step:
            self._cpos = kern.push(self._cbuf, self._cpos, self.coarse_blocks, self._csum / self.coarse_step)
            self._ccount = min(self._ccount + 1, self.coarse_blocks)
            self._csum[:] = 0.0
            self._cn = 0

    def _matrix(self, data: np.ndarray) -> sp.csr_matrix:
        """scipy (3N, 3N) matrix of block data (B, 9)."""
        n3 = 3 * self.n_nodes
        return sp.bsr_matrix((data.reshape(-1, 3, 3), self._indices, self._indptr), shape=(n3, n3)).tocsr()

    def _on_material_changed(self, name: str) -> None:
        """Contract v2 ``scale_material`` / ``set_field`` hook: re-derive stiffness, masses, damping;
        drop the LU and the critical dt."""
        self._build_material()

    # ------------------------------------------------------------------------------------------
    # stepping
    def current_order(self, time: float | None = None) -> float:
        """q at ``time`` (default: the model's time)."""
        return float(self.order(self.time if time is None else time))

    def _advance(self, dt: float, forces: np.ndarray, stiffness) -> None:
        q = self.current_order()
        w = self._gl(q)
        a_f = self._branch(q)
        c = dt ** -q
        fext = np.ascontiguousarray(forces, dtype=np.float64).reshape(-1)
        x = self.positions.reshape(-1)
        v = self.velocities.reshape(-1)
        d, s, f = self._work
        mem = self.memory
        if self.active_integrator == "symplectic":
            # s_n = w_0 d_n + sum_{k>=1} w_k d_{n-k}: d_n is the current state (ring row 0 holds the
            # end of the previous step, equal to it unless set_fixed moved nodes in between)
            older = min(max(self._count - 1, 0), mem)
            remote = self._remote_sum(q, 0)
            kern.symplectic_step(x, v, self._rest_flat, self._buf, self._pos + 1, older, w, self._indptr,
                                 self._indices, self._a_inf, a_f, c, fext, self._inv_m, self._alpha_node, dt,
                                 self.gravity, ~self.fixed, remote, d, s, f)
            self._s_last[:] = s
        else:
            self._implicit(dt, w, a_f, c, fext, x, v, d, s, f)
        self._c_last = c
        np.subtract(x, self._rest_flat, out=d)
        self._pos = kern.push(self._buf, self._pos, mem + 1, d)
        self._count = min(self._count + 1, mem + 1)
        self._push_coarse(d)
        self.integrated_external_forces = np.asarray(forces, dtype=np.float64).reshape(-1, 3).copy()

    def _implicit(self, dt, w, a_f, c, fext, x, v, d, s, f) -> None:
        """Backward Euler with s_{n+1} = w_0 d_{n+1} + sum_{k=1}^{L} w_k d_{n+1-k} (ring rows k-1):
        [M(1 + alpha dt) + dt^2 (K_inf + c w_0 K_f)] v+ = M v + dt (f_ext + m g - K_inf d - c K_f
        (w_0 d + hist)), d the current displacement, x+ = x + dt v+."""
        n = self.n_nodes
        q = self.current_order()
        kern.history_sum(self._buf, self._pos, min(self._count, self.memory), w[1:], s)
        s += self._remote_sum(q, 1)
        hist = s.copy()
        np.subtract(x, self._rest_flat, out=d)
        s += w[0] * d
        kern.branch_forces(self._indptr, self._indices, self._a_inf, a_f, d, s, c, f)
        m3 = np.repeat(self.masses, 3)
        rhs = m3 * v + dt * (f + fext + np.tile(self.gravity, n) * m3)
        free3 = np.repeat(~self.fixed, 3)
        lu, a_fc = self._factor(dt, q, c, a_f, w[0], free3)
        v_new = np.zeros_like(v)
        fixed3 = ~free3
        if fixed3.any():
            v_new[fixed3] = (self.fixed_targets.reshape(-1)[fixed3] - x[fixed3]) / dt
            rhs_f = rhs[free3] - a_fc @ v_new[fixed3]
        else:
            rhs_f = rhs[free3]
        v_new[free3] = lu.solve(rhs_f)
        v[:] = v_new
        x += dt * v
        self._s_last[:] = hist + w[0] * (x - self._rest_flat)      # s_{n+1}, for stresses and internal_forces

    def _factor(self, dt, q, c, a_f, w0, free3):
        key = (dt, q)
        if self._lu is not None and self._lu[0] == key and np.array_equal(self._lu[1], free3):
            return self._lu[2], self._lu[3]
        m3 = np.repeat(self.masses * (1.0 + self._alpha_node * dt), 3)
        a = (sp.diags(m3) + dt * dt * self._matrix(self._a_inf + c * w0 * a_f)).tocsr()
        lu = spla.splu(a[free3][:, free3].tocsc())
        a_fc = a[free3][:, ~free3].tocsr()
        self._lu = (key, free3.copy(), lu, a_fc)
        return lu, a_fc

    def _on_fixed_changed(self) -> None:
        if hasattr(self, "_lu"):
            self._lu = None

    def _reset_state(self) -> None:
        self._buf[:] = 0.0
        self._pos = self.memory + 1
        self._count = 0
        self._cbuf[:] = 0.0
        self._clear_coarse()
        self._s_last[:] = 0.0
        self._c_last = 0.0
        self.integrated_external_forces = np.zeros_like(self.positions)

    # ------------------------------------------------------------------------------------------
    # stability
    def critical_dt(self) -> float:
        """Largest stable dt (s) of the symplectic integrator, no safety factor.

        For a mode with omega_inf^2 (of M^-1 K_inf) and omega_f^2 (of M^-1 K_f), the step's
        characteristic equation ``zeta - 2 + 1/zeta = -dt^2 omega_inf^2 - dt^(2-q) omega_f^2
        (1 - 1/zeta)^q`` reaches zeta = -1 when ``dt^2 omega_inf^2 + 2^q dt^(2-q) omega_f^2 = 4``;
        solved by bisection with the largest eigenvalues (Lanczos, bounds added), for every order
        of the schedule (the smallest root wins). Cached; reset when the material changes."""
        if self._crit is None:
            lam_inf = self._lambda_max(self._a_inf)
            crit = math.inf
            for q in sorted(set(self.order.values)):      # the most restrictive piece of the schedule
                lam_f = self._lambda_max(self._scatter(self.fields["relax_fraction"] * self.fields["relax_time"] ** q))
                crit = min(crit, self._root(lam_inf, lam_f, q))
            self._crit = crit
        return self._crit

    @staticmethod
    def _root(lam_inf: float, lam_f: float, q: float) -> float:
        """dt with dt^2 lam_inf + 2^q dt^(2-q) lam_f = 4 (bisection; inf if none below 1 s)."""
        def lhs(dt):
            return lam_inf * dt * dt + 2 ** q * dt ** (2 - q) * lam_f

        lo, hi = 0.0, 1.0
        if lhs(hi) <= 4.0:
            return math.inf
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if lhs(mid) > 4.0:
                hi = mid
            else:
                lo = mid
        return lo

    def _lambda_max(self, data: np.ndarray) -> float:
        if not np.any(data):
            return 0.0
        free3 = np.repeat(~self.fixed, 3) if self.fixed.any() else np.ones(3 * self.n_nodes, dtype=bool)
        sm = np.repeat(1.0 / np.sqrt(self.masses), 3)
        k = self._matrix(data)
        a = (sp.diags(sm) @ k @ sp.diags(sm)).tocsr()[free3][:, free3]
        v0 = np.cos(np.arange(a.shape[0]) * 0.7071)            # fixed start vector: reproducible dt
        val = spla.eigsh(a, k=1, which="LA", return_eigenvectors=False, tol=1e-6, maxiter=5000, v0=v0)
        return float(val[0]) * 1.0001

    # ------------------------------------------------------------------------------------------
    # forces, energies, fields
    def elastic_energy(self) -> float:
        """0.5 d^T K d (J), K the elastic stiffness of (young, poisson): the energy of the elastic
        response that the law differentiates (the q -> 0 limit; the branch itself dissipates)."""
        d = self.positions.reshape(-1) - self._rest_flat
        return 0.5 * kern.block_quadratic(self._indptr, self._indices, self._a_el, d)

    def internal_forces(self) -> np.ndarray:
        """(N,3) N: -K_inf d - dt^-q K_f s at the last step (s the weighted displacement history)."""
        d = self.positions.reshape(-1) - self._rest_flat
        out = np.zeros_like(d)
        a_f = self._branch(self.current_order())
        kern.branch_forces(self._indptr, self._indices, self._a_inf, a_f, d, self._s_last, self._c_last, out)
        return out.reshape(-1, 3) - (self._alpha_node * self.masses)[:, None] * self.velocities

    def inverted_elements(self) -> int:
        return int(count_inverted(self.positions, self.tets))

    def element_stress(self) -> np.ndarray:
        """(T,3,3) Cauchy stress (Pa) per tet: (1 - g) C eps(d_n) + g tau^q dt^-q C eps(s_n), s_n the
        GL-weighted displacement history of the last step (small strain)."""
        t = len(self.tets)
        d = (self.positions - self.rest_positions)[self.tets].reshape(t, 12)
        s = self._s_last.reshape(-1, 3)[self.tets].reshape(t, 12)
        g = self.fields["relax_fraction"]
        q = self.current_order()
        mix = (1 - g)[:, None] * np.einsum("tij,tj->ti", self._b, d) + \
            (g * self.fields["relax_time"] ** q * self._c_last)[:, None] * np.einsum("tij,tj->ti", self._b, s)
        v = np.einsum("tij,tj->ti", asm.d_matrices(self.fields["young"], self.fields["poisson"]), mix)
        out = np.empty((t, 3, 3))
        out[:, 0, 0], out[:, 1, 1], out[:, 2, 2] = v[:, 0], v[:, 1], v[:, 2]
        out[:, 0, 1] = out[:, 1, 0] = v[:, 3]
        out[:, 1, 2] = out[:, 2, 1] = v[:, 4]
        out[:, 0, 2] = out[:, 2, 0] = v[:, 5]
        return out

    def _node_field(self, name: str) -> np.ndarray:
        """``order``: the current q at every node (uniform; q is a function of time)."""
        return np.full(self.n_nodes, self.current_order())

    # ------------------------------------------------------------------------------------------
    def static_solve(self, forces: np.ndarray | None = None, **kwargs) -> np.ndarray:
        """Long-time (fully relaxed, infinite-memory) equilibrium positions (N,3) m under
        ``forces`` (N,3) N (+ gravity) and the Dirichlet nodes: ``K_inf u = f``. When every element
        is pure fractional (g = 1) there is no equilibrium under a load (the law creeps as t^q);
        with loads only through the Dirichlet nodes the equilibrium is the elastic one, ``K u = 0``
        on the free nodes (the relaxation mode of the variable-order paper, eqs. 22-23). Sets ``positions``."""
        if not self.fixed.any():
            raise ConfigError("static_solve needs Dirichlet nodes (the free body has rigid modes); call set_fixed(nodes) first")
        forces = self.external_forces if forces is None else np.asarray(forces, dtype=np.float64)
        if forces.shape != self.positions.shape or not np.all(np.isfinite(forces)):
            raise ConfigError(f"forces must be a finite array of shape {self.positions.shape}")
        load = (forces + self.masses[:, None] * self.gravity[None, :]).reshape(-1)
        free3 = np.repeat(~self.fixed, 3)
        data = self._a_inf
        if not np.any(data):
            if np.any(load[free3]):
                raise ConfigError("a pure fractional tissue (relax_fraction = 1 everywhere) has no equilibrium under a "
                                  "constant load: it creeps as t^q; give relax_fraction < 1 or load through Dirichlet nodes")
            data = self._a_el
        k = self._matrix(data)
        u = np.zeros(3 * self.n_nodes)
        u[~free3] = (self.fixed_targets - self.rest_positions).reshape(-1)[~free3]
        rhs = load[free3] - k[free3][:, ~free3] @ u[~free3]
        u[free3] = spla.spsolve(k[free3][:, free3].tocsc(), rhs)
        self.positions = self.rest_positions + u.reshape(-1, 3)
        self.velocities = np.zeros_like(self.positions)
        return self.positions.copy()

    def describe(self) -> dict:
        out = super().describe()
        out.update(order=list(self.order.values), order_breaks_s=list(self.order.breaks), memory=self.memory,
                   coarse_blocks=self.coarse_blocks, coarse_step=self.coarse_step,
                   memory_span_steps=self.memory + self.coarse_blocks * self.coarse_step)
        return out
