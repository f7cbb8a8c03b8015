"""Quasi-static linear tet FEM with a prefactored stiffness and contact condensation: FEM
accuracy at the cost of a small dense solve per step.

The elastic body is the ``fem`` model's small-strain one (linear 4-node tets, locking-free
averaged nodal pressure, ANP, by default), without inertia: every step returns the equilibrium

    K u = f + f_D + f_g,     u = x - X                                                   (1)

(f the external nodal forces, f_D the reaction of moved Dirichlet targets, f_g gravity). K is
factorised once (sparse LU, symmetric ordering) on the free dofs. A step does not solve (1):
only the nodes A carrying a force or a contact stiffness enter, through their compliance columns
``C_A = K^-1 P_A^T`` (back-substituted on first contact and cached, :mod:`compliance`):

    (I + W_AA k_A) u_A = u0_A + W_AA (f_A + k_A u_A^n),   W_AA = P_A C_A                   (2)
    g_A = f_A - k_A (u_A - u_A^n),     u = u0 + C_A g_A                                      (3)

with k_A the scene's penalty contact stiffness (N/m per node, isotropic) integrated implicitly
(the contact force linearised about the previous state x^n), u0 the response to Dirichlet targets
and gravity (a full solve, only when they change) and g_A the external force actually integrated
(``integrated_external_forces``; the tools get exactly its reaction). Equations (2)-(3) are (1)
with the linearised penalty exactly: the condensation loses nothing (tests compare it with a full
sparse solve). Cost per step: a 3|A| x 3|A| dense solve and one 3N x 3|A| product.

Viscoelasticity (``viscoelastic="auto"``, the default). A material with a relax fraction g and
time tau relaxes by the ``fem`` model's standard linear solid (:mod:`fem_viscous`: the stress
``(1 - g) sigma0 + g h``, ``h`` the hereditary integral of ``sigma0`` with kernel exp(-t/tau)). When
every element shares g and tau (a lump that only scales E keeps them), the stiffness factors as
``K(t) = K0 (1 - g + g exp(-t/tau))``: the hereditary integral lives in displacement space, one
vector H (3N,) m, and a step of h s with the exact piecewise-linear update of ``fem_viscous``
(decay = exp(-h/tau), gamma = tau/h (1 - decay), c = 1 - g + g gamma) is

    K0 (c u + s) = f,   s = g (decay H_n - gamma u_n),   H_{n+1} = decay H_n + gamma (u - u_n)   (4)

So ``w = c u + s`` is the elastic solution of (1) for the same loads (with Dirichlet targets
``c u_D + s_D``), and (2)-(3) hold for w with W_AA / c and u0 -> (u0 - s) / c: the same
factorisation and cached columns, plus O(N) vector work per step. Held still, the force relaxes
to (1 - g) of its instantaneous value with time constant tau; under a held force the body creeps
to 1 / (1 - g) of its instantaneous displacement. When g or tau differ between elements the
stiffness does not factor, and the model gives the long-term (relaxed) equilibrium, moduli
x (1 - g), as ``fem.static_solve`` does (``viscoelastic="relaxed"`` asks for that always).

Choices: small strain (no corotation: a rotating element would change K and void the cached
columns; the indentation depths of the benchmark are <= 0.3 R); the symmetry planes of a quarter
model may be held per dof with ``fixed_dofs``. See docs/models/fem_static.md.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
from numba import njit

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError, TissueUnstableError
from surgsim_envs.tissue import fem_assembly as asm
from surgsim_envs.tissue import fem_viscous as visc
from surgsim_envs.tissue.compliance import (DEFAULT_CACHE_MB, SOLVERS, CondensedCompliance, respond,
                                             scaled_block)
from surgsim_envs.contact_law.plane import PlaneContactLaw
from surgsim_envs.tissue.condensed_plane_solve import condensed_plane_solve, find_loaded_law
from surgsim_envs.tissue.dense_solve import solve_dense
from surgsim_envs.tissue.fem import TetFEMModel
from surgsim_envs.tissue.guard import StabilityGuard


#: a step with the contact's plane law sweeps its pairs until no pair's force moves by more than
#: this share of the largest (:mod:`condensed_plane_solve`)
PLANE_LAW_TOLERANCE = 1e-6
#: at most this many sweeps
PLANE_LAW_SWEEPS = 500
#: fem_static's treatments of a viscoelastic material (see the module docstring)
VISCOELASTIC_MODES = ("auto", "hereditary", "relaxed")


@njit(cache=True, nogil=True)
def find_loaded(forces, kc, held, out):
    """Write into ``out`` the free nodes with a non-zero force (N,3) or contact stiffness (N,);
    return their count."""
    m = 0
    for i in range(forces.shape[0]):
        if held[i]:
            continue
        if kc[i] > 0.0 or forces[i, 0] != 0.0 or forces[i, 1] != 0.0 or forces[i, 2] != 0.0:
            out[m] = i
            m += 1
    return m


@njit(cache=True, nogil=True)
def hereditary_shift(g, decay, gamma, hist, u_step, out):
    """``out`` (3N,) = s of equation (4): g (decay H - gamma u_n), in place (the numpy expression's
    operation order, so the result is the same to the bit)."""
    for i in range(out.shape[0]):
        out[i] = g * (decay * hist[i] - gamma * u_step[i])


@njit(cache=True, nogil=True)
def hereditary_base_displacement(w0, s, c, out):
    """``out`` (3N,) = (w0 - s) / c: u0 of the hereditary step (equation (4)), in place."""
    for i in range(out.shape[0]):
        out[i] = (w0[i] - s[i]) / c


@njit(cache=True, nogil=True)
def hereditary_advance(u, decay, gamma, hist, u_step):
    """After a step: H <- decay H + gamma (u - u_n), then u_n <- u (equation (4)), in place, in the
    numpy expression's operation order."""
    for i in range(u.shape[0]):
        h = hist[i] * decay
        hist[i] = h + gamma * (u[i] - u_step[i])
        u_step[i] = u[i]


@njit(cache=True, nogil=True)
def held_targets(c, u_d, s, held, out):
    """``out`` (h,) = c u_d + s on the ``held`` dofs: the Dirichlet values of the hereditary base
    (equation (4)), in the numpy expression's operation order."""
    for k in range(held.shape[0]):
        d = held[k]
        out[k] = c * u_d[d] + s[d]


@njit(cache=True, nogil=True)
def has_negative(values):
    """Whether any entry of ``values`` (1-D) is below zero (``np.any(values < 0)``)."""
    for i in range(values.shape[0]):
        if values[i] < 0.0:
            return True
    return False


@njit(cache=True, nogil=True)
def commit_positions(u, rest, positions, velocities, dt):
    """positions = rest + u (u (3N,) m), velocities = finite difference over ``dt`` s, in place."""
    for i in range(rest.shape[0]):
        for j in range(3):
            x = rest[i, j] + u[3 * i + j]
            velocities[i, j] = (x - positions[i, j]) / dt
            positions[i, j] = x


@njit(cache=True, nogil=True)
def condensed_contact_solve(cols, slots, loaded, u0, forces, kc, use_kc, positions, rest, c, u, applied):
    """One quasi-static step on the condensed loaded nodes (equations (2)-(3)): W (3m,3m) gathered
    from the cached compliance columns ``cols[slots]`` and divided by ``c``; with contact stiffness
    (``use_kc``) the loaded dofs solve ``(I + W k) u_A = u0_A + W (f + k u_n)`` and carry
    ``g = f - k (u_A - u_n)``, else ``g = f``. Writes u (3N,) = u0 + C_A g / c and ``applied[loaded]`` =
    g (N). The small system is solved by :func:`~surgsim_envs.tissue.dense_solve.solve_dense`."""
    m = loaded.shape[0]
    n3 = 3 * m
    w = scaled_block(cols, slots, loaded, c)
    g = np.empty(n3)
    for b in range(m):
        for j in range(3):
            g[3 * b + j] = forces[loaded[b], j]
    if use_kc:
        k_a = np.empty(n3)
        un_a = np.empty(n3)
        v = np.empty(n3)
        rhs = np.empty(n3)
        for b in range(m):
            i = loaded[b]
            for j in range(3):
                d = 3 * b + j
                k_a[d] = kc[i]
                un_a[d] = positions[i, j] - rest[i, j]
                v[d] = g[d] + k_a[d] * un_a[d]
        for b in range(m):
            for j in range(3):
                d = 3 * b + j
                wv = 0.0                     # (W v)_d as a loop: numba's matmul wrapper costs seconds to compile
                for e in range(n3):
                    wv += w[d, e] * v[e]
                rhs[d] = u0[3 * loaded[b] + j] + wv
        a = np.empty((n3, n3))
        for i in range(n3):
            for j in range(n3):
                a[i, j] = (1.0 if i == j else 0.0) + w[i, j] * k_a[j]
        u_a = solve_dense(a, rhs)
        for d in range(n3):
            g[d] = g[d] - k_a[d] * (u_a[d] - un_a[d])
    respond(cols, slots, loaded, g, c, u0, u, applied)


class QuasiStaticFEMModel(TetFEMModel):
    """Quasi-static small-strain tet FEM with a prefactored stiffness and condensed contact
    (module docstring).

    Parameters (besides ``volume``, ``material``, ``fixed``, ``gravity``, ``region_materials``)
    ----------
    formulation: ``"anp"`` (averaged nodal pressure, locking-free; default) or ``"standard"``.
    fixed_dofs: optional (N,3) bool, single dofs held at their rest coordinate (rollers, symmetry
        planes) in addition to the fixed nodes.
    cache_mb: memory (MB) for cached compliance columns (72 x N bytes per loaded node; least
        recently used evicted beyond it).
    solver: the sparse factorisation of K: ``"superlu"`` (default), ``"pardiso"`` (MKL PARDISO's
        Cholesky, needs the optional package pypardiso; several times faster on large meshes) or
        ``"auto"`` (pardiso when installed), see :mod:`surgsim_envs.tissue.compliance`.
    precompute: None (columns on first contact, default), ``"surface"`` (every free surface node,
        at build) or node indices: back-substitute those columns at build so that no step pays
        for a first contact (:meth:`precompute`).
    viscoelastic: ``"auto"`` (default: the hereditary standard linear solid of equation (4) when
        every element shares the relax fraction and time, else the relaxed equilibrium),
        ``"hereditary"`` (ConfigError when they differ) or ``"relaxed"`` (the long-term
        equilibrium, moduli x (1 - relax_fraction)).
    """

    name: ClassVar[str] = "fem_static"
    summary: ClassVar[str] = ("quasi-static small-strain tet FEM (ANP): prefactored sparse LU, contact condensed "
                              "on cached compliance columns (SOFA precomputed compliance)")
    integrators: ClassVar[tuple[str, ...]] = ("quasi_static",)
    auto_pair = None
    default_integrator = None
    resolves_contact_set = True
    capabilities = frozenset({"forces", "unstructured_mesh", "implicit_contact", "quasi_static", "static_solve",
                              "subsurface_stiffness", "viscoelastic", "condensed_compliance",
                              "plane_contact_law"})
    material_fields = ("young", "poisson", "density")

    def __init__(self, volume, material="liver", *, formulation: str = "anp", fixed_dofs=None,
                 cache_mb: float = DEFAULT_CACHE_MB, solver: str = "superlu", precompute=None, integrator: str | None = None,
                 corotational: bool = False, viscoelastic: str = "auto", **base_kwargs):
        if corotational:
            raise ConfigError("fem_static is small-strain only (corotational=False): its factorised stiffness and "
                              "cached compliance are valid for one K; use model 'fem' for large rotations")
        for key in ("stiffness_damping", "rotation_iters", "cg_tol", "threads", "preconditioner"):
            if key in base_kwargs:
                raise ConfigError(f"fem_static has no option {key!r} (it has no dynamic integrator); options: "
                                  "formulation, fixed_dofs, cache_mb, solver, viscoelastic, fixed, gravity, "
                                  "region_materials")
        self.viscoelastic = validate.choice(viscoelastic, "fem_static: viscoelastic", VISCOELASTIC_MODES,
                                            fix="'auto', 'hereditary' or 'relaxed'")
        self.hereditary = None            # (g, tau) of equation (4) when the model steps it, else None
        self.cache_mb = validate.positive(cache_mb, "fem_static: cache_mb", unit="MB",
                                          fix="the memory of cached compliance rows, e.g. 256")
        self.solver = validate.choice(solver, "fem_static: solver", SOLVERS,
                                      fix="'superlu', 'pardiso' (needs pypardiso) or 'auto'")
        self._comp: CondensedCompliance | None = None
        if base_kwargs.get("guard") is None:
            # a linear solve with a factorised SPD stiffness cannot diverge: an inverted element means
            # the load is beyond small strain (an accuracy limit, see inverted_elements()), not an
            # instability, so the guard checks only non-finite states and speeds
            # (and its energy check, which evaluates the elastic energy, runs every 100 steps); as for every
            # quasi-static model, a node may jump up to the body's size in one step (TissueModel)
            base_kwargs["guard"] = StabilityGuard(check_inversion=False, check_every=100)
        super().__init__(volume, material, integrator=integrator, corotational=False, formulation=formulation,
                         **base_kwargs)
        n = self.n_nodes
        self.fixed_dofs = np.zeros((n, 3), dtype=bool)
        if fixed_dofs is not None:
            fd = np.asarray(fixed_dofs)
            if fd.dtype != bool or fd.shape != (n, 3):
                raise ConfigError(f"fem_static: fixed_dofs must be an ({n}, 3) bool array (True = dof held at its "
                                  f"rest coordinate), got dtype {fd.dtype} shape {fd.shape}")
            self.fixed_dofs = fd.copy()
        self.fixed_dofs.setflags(write=False)      # set at build: the factorisation depends on it
        self._u0 = np.zeros(3 * n)             # response to Dirichlet targets and gravity (m)
        self._u0_stale = True
        self._hist = np.zeros(3 * n)           # H of equation (4), m
        self._u_step = np.zeros(3 * n)         # u at the end of the last step (equation (4)'s u_n), m
        self._shift_buf = np.zeros(3 * n)      # s of equation (4), m (rewritten every step)
        self._u0_buf = np.zeros(3 * n)         # u0 of the hereditary step, m (rewritten every step)
        self._u_buf = np.zeros(3 * n)          # u of the step, m (rewritten every step)
        self._branch_key, self._branch_value = None, (1.0, 1.0)
        self._wd_key = None                    # Dirichlet targets of the cached elastic response (equation (4))
        self._held_dofs, self._held_of = np.zeros(0, dtype=np.int64), None
        self.last_loaded = 0
        self._loaded_buf = np.zeros(n, dtype=np.int64)
        self._zero_kc = np.zeros(n)
        self._mark = np.zeros(n, dtype=np.int64)
        self._slot_of = np.full(n, -1, dtype=np.int64)
        #: Gauss-Seidel sweeps of the last step with the contact's plane law (``PLANE_LAW_SWEEPS + 1``:
        #: stopped before the tolerance)
        self.last_sweeps = 0
        if isinstance(precompute, str):
            if precompute != "surface":
                raise ConfigError(f"fem_static: precompute={precompute!r}; use None, 'surface' or node indices")
            precompute = self.surface_nodes[~self.fixed[self.surface_nodes]]
        if precompute is not None:
            self.precompute(precompute)

    # ------------------------------------------------------------------------------------------
    # Material: the long-term (relaxed) elastic body; factorisation dropped on change
    def _setup_material(self) -> None:
        super()._setup_material()
        self.hereditary = None
        if self._visco:
            g, tau = self.relax_g, self.relax_tau
            uniform = bool(np.all(g == g[0]) and np.all(tau == tau[0]))
            mode = getattr(self, "viscoelastic", "auto")
            if mode == "hereditary" and not uniform:
                raise ConfigError(
                    "fem_static: viscoelastic='hereditary' needs one relax_fraction and relax_time for every element "
                    f"(here relax_fraction {float(g.min()):g}..{float(g.max()):g}, relax_time {float(tau.min()):g}.."
                    f"{float(tau.max()):g} s): the stiffness then factors as K0 (1 - g + g exp(-t/tau)); use "
                    "viscoelastic='relaxed' (the long-term equilibrium) or the dynamic model 'fem'")
            if uniform and mode != "relaxed":
                self.hereditary = (float(g[0]), float(tau[0]))   # K0 stays the instantaneous stiffness
            else:                            # quasi-static: relaxed moduli, E (1 - relax_fraction)
                r = 1.0 - self.relax_g
                self.mu, self.lam, self._kappa_el = self.mu * r, self.lam * r, self._kappa_el * r
                self._ke = self._ke * r[:, None, None]
                self.kappa_node = asm.nodal_average(self.tets, self.tet_volume, self._kappa_el, self.n_nodes)
                self._k_rest = self._assemble_stiffness(None)
            self._visco = False
        self._comp = None
        self._comp_version = -1
        self._u0_stale = True
        self._wd_key = None

    def _on_fixed_changed(self) -> None:
        self._u0_stale = True                 # the factorisation is rebuilt if the fixed dofs changed
        self._fixed_version = getattr(self, "_fixed_version", 0) + 1

    def critical_dt(self, method: str = "spectral") -> float:
        """No explicit integrator: unconditionally stable (inf)."""
        return math.inf

    # ------------------------------------------------------------------------------------------
    # Factorisation
    def _free_mask(self) -> np.ndarray:
        held = self.fixed_dofs | self.fixed[:, None]
        return ~held.reshape(-1)

    def compliance(self) -> CondensedCompliance:
        """The factorised stiffness with its column cache (rebuilt when the material or the fixed dofs change)."""
        version = getattr(self, "_fixed_version", 0)
        if self._comp is not None and self._comp_version == version:
            return self._comp
        free = self._free_mask()
        self._comp_version = version
        if self._comp is None or not np.array_equal(self._comp.free, free):
            if free.all():
                raise ConfigError("fem_static needs fixed nodes (a free body has rigid modes): pass fixed=... or "
                                  "call set_fixed(nodes)")
            self._comp = CondensedCompliance(self._k_rest, free, cache_mb=self.cache_mb, solver=self.solver)
            self._u0_stale = True
        return self._comp

    def precompute(self, nodes) -> None:
        """Back-substitute and cache the compliance columns of ``nodes`` now (e.g. the surface a tool
        can touch), so that the first contact there costs no solve."""
        idx = self._as_indices(nodes, "precompute nodes")
        comp = self.compliance()
        if len(idx) > comp.capacity:
            raise ConfigError(f"fem_static: precomputing {len(idx)} nodes needs cache_mb >= "
                              f"{72.0 * self.n_nodes * len(idx) / 1e6:.0f} (now {self.cache_mb:g})")
        for chunk in np.array_split(idx, max(1, math.ceil(len(idx) / 64))):
            comp.slots(chunk)

    def _base_displacement(self) -> np.ndarray:
        """u0 (3N,) m: equilibrium under the Dirichlet targets and gravity, without external forces."""
        if self._u0_stale:
            uc = np.zeros(3 * self.n_nodes)
            fx = self.fixed
            uc.reshape(-1, 3)[fx] = (self.fixed_targets[fx] - self.rest_positions[fx])
            self._u0 = self._elastic_response(uc)
            self._u0_stale = False
        return self._u0

    def _elastic_response(self, uc: np.ndarray) -> np.ndarray:
        """(3N,) m: K0's equilibrium under gravity with the held dofs at ``uc`` (zero elsewhere)."""
        comp = self.compliance()
        load = (self.masses[:, None] * self.gravity[None, :]).ravel() - self._k_rest @ uc
        u = comp.solve(np.where(comp.free, load, 0.0)) if (np.any(uc) or np.any(self.gravity)) else np.zeros(uc.shape)
        return u + uc

    def _branch(self, dt: float, tau: float) -> tuple[float, float]:
        """(decay, gamma) of equation (4) for a step of ``dt`` s, kept while dt and tau stay the same."""
        if self._branch_key != (dt, tau):
            decay_a, gamma_a = visc.branch_coefficients(dt, np.array([tau]))
            self._branch_key, self._branch_value = (dt, tau), (float(decay_a[0]), float(gamma_a[0]))
        return self._branch_value

    def _hereditary_base(self, c: float, s: np.ndarray) -> np.ndarray:
        """w0 (3N,) of equation (4): K0's equilibrium under gravity with the Dirichlet dofs at
        ``c u_D + s_D`` (cached while those stay the same, e.g. nodes held at rest)."""
        comp = self.compliance()
        u_d = self._base_displacement()
        if self._held_of is not comp:                 # the held dofs of this factorisation
            self._held_dofs, self._held_of = np.flatnonzero(~comp.free), comp
            self._held_bytes, self._wd_held = self._held_dofs.tobytes(), np.empty(len(self._held_dofs))
        held = self._held_dofs
        wd_held = self._wd_held
        held_targets(c, u_d, s, held, wd_held)       # only the held dofs enter: the key costs O(held), not O(N)
        key = (c, self._held_bytes, wd_held.tobytes())
        if self._wd_key != key:
            wd = np.zeros(3 * self.n_nodes)
            wd[held] = wd_held
            self._w0 = self._elastic_response(wd)
            self._wd_key = key
        return self._w0

    # ------------------------------------------------------------------------------------------
    # Step: equations (2)-(3) of the module docstring
    def _advance(self, dt: float, forces: np.ndarray, stiffness) -> None:
        comp = self.compliance()
        u0 = self._base_displacement()
        c, s, decay, gamma = 1.0, None, 1.0, 1.0
        if self.hereditary is not None:               # equation (4): w = c u + s solves (1)
            g, tau = self.hereditary
            decay, gamma = self._branch(dt, tau)
            c = 1.0 - g + g * gamma
            # u_n is the last step's own result: Dirichlet targets moved since (set_fixed) enter the
            # hereditary integral over this step, as a ramp, like every other displacement
            s = self._shift_buf
            hereditary_shift(g, decay, gamma, self._hist, self._u_step, s)
            u0 = self._u0_buf
            hereditary_base_displacement(self._hereditary_base(c, s), s, c, u0)
        held = self.fixed
        if isinstance(stiffness, PlaneContactLaw):
            self._advance_plane_law(comp, u0, c, forces, stiffness, held)
        else:
            self._advance_linearised(comp, u0, c, forces, stiffness, held)
        u = self._u_buf
        if s is not None:
            hereditary_advance(u, decay, gamma, self._hist, self._u_step)
        commit_positions(u, self.rest_positions, self.positions, self.velocities, dt)
        self.external_forces = forces

    def _advance_plane_law(self, comp, u0, c, forces, law, held) -> None:
        """Equations (2)-(3) with the contact's plane law solved exactly (:mod:`condensed_plane_solve`)."""
        if law.count and not np.isfinite(law.data[:law.count]).all():
            raise ConfigError("fem_static: the contact's plane law holds non-finite values")
        count = find_loaded_law(forces, law.nodes, law.count, held, self._mark, self._loaded_buf)
        loaded = self._loaded_buf[:count]
        self.last_loaded = count
        u = self._u_buf
        if count:
            self.last_sweeps = condensed_plane_solve(
                comp.cols, comp.slots(loaded), loaded, u0, forces, law.nodes, law.data, law.count, self.positions,
                self.rest_positions, c, u, self.integrated_external_forces, PLANE_LAW_TOLERANCE, PLANE_LAW_SWEEPS,
                self._slot_of)
        else:
            u[:] = u0

    def _advance_linearised(self, comp, u0, c, forces, stiffness, held) -> None:
        """Equations (2)-(3): the contact force linearised with the isotropic ``stiffness`` (N,) N/m."""
        n = self.n_nodes
        if stiffness is not None:
            kc = np.asarray(stiffness, dtype=np.float64)
            if kc.shape != (n,) or has_negative(kc):
                raise ConfigError(f"fem_static: stiffness must be (N,) >= 0 N/m, got shape {kc.shape}")
        else:
            kc = None
        count = find_loaded(forces, self._zero_kc if kc is None else kc, held, self._loaded_buf)
        loaded = self._loaded_buf[:count]
        u = self._u_buf
        self.last_loaded = len(loaded)
        if len(loaded):
            slots = comp.slots(loaded)
            condensed_contact_solve(comp.cols, slots, loaded, u0, forces, self._zero_kc if kc is None else kc,
                                    kc is not None, self.positions, self.rest_positions, c, u,
                                    self.integrated_external_forces)
        else:
            u[:] = u0

    def _step_body(self, dt: float, forces: np.ndarray, stiffness) -> None:
        try:
            super()._step_body(dt, forces, stiffness)
        except TissueUnstableError as exc:
            # the equilibrium solve cannot diverge; only forces computed from the finite-difference
            # velocity (explicit contact damping) can drive it: say so instead of "reduce dt"
            raise TissueUnstableError(exc.model, exc.dt, exc.critical_dt, exc.reason + (
                "; fem_static is quasi-static (no dt limit): a divergence comes from explicit forces "
                "that depend on its finite-difference velocities, such as contact damping: lower the "
                "contact damping (ContactParams.damping / ContactConfig.damping, e.g. <= 0.1 N s/m), "
                "raise dt, or make the damping implicit (ContactParams(implicit_damping=True); scenes do "
                "it for quasi-static models with ContactConfig.implicit_damping='auto')")) from None

    def internal_forces(self) -> np.ndarray:
        """(N,3) N elastic nodal forces (no inertia, no viscous term: quasi-static): -K u, or with the
        hereditary law -K0 ((1 - g) u + g H)."""
        if self.hereditary is None:
            return self.elastic_forces()
        g = self.hereditary[0]
        u = (self.positions - self.rest_positions).reshape(-1)
        return -(self._k_rest @ ((1.0 - g) * u + g * self._hist)).reshape(-1, 3)

    # ------------------------------------------------------------------------------------------
    def static_solve(self, forces=None, stiffness=None, **kwargs) -> np.ndarray:
        """Equilibrium positions (N,3) m under ``forces`` (N,3) N (default: the last ones) and the
        Dirichlet targets: one full back-substitution (no condensation); with the hereditary law the
        long-term one (fully relaxed, H = 0). Updates ``positions`` (velocities zeroed) and returns a
        copy. ``stiffness`` is not accepted (no contact state)."""
        if stiffness is not None:
            raise ConfigError("fem_static.static_solve takes no contact stiffness; use step(dt, forces, stiffness)")
        if kwargs:
            raise ConfigError(f"fem_static.static_solve has no options {sorted(kwargs)}")
        f = self.external_forces if forces is None else np.asarray(forces, dtype=np.float64)
        if f.shape != self.positions.shape or not np.all(np.isfinite(f)):
            raise ConfigError(f"forces must be a finite array of shape {self.positions.shape}, got {f.shape}")
        comp = self.compliance()
        u = self._base_displacement() + comp.solve(np.where(comp.free, f.reshape(-1), 0.0))
        if self.hereditary is not None:    # relaxed stiffness (1 - g) K0: the loads' response / (1 - g)
            uc = np.where(comp.free, 0.0, u)
            load = (self.masses[:, None] * self.gravity[None, :]).ravel() + f.reshape(-1)
            u = (uc + comp.solve(np.where(comp.free, load, 0.0)) / (1.0 - self.hereditary[0])
                 + (comp.solve(np.where(comp.free, -(self._k_rest @ uc), 0.0)) if np.any(uc) else 0.0))
            self._hist[:] = 0.0
            self._u_step[:] = u
        self.positions = self.rest_positions + u.reshape(-1, 3)
        self.velocities = np.zeros_like(self.positions)
        return self.positions.copy()

    def _require_elastic(self, what: str) -> None:
        """The condensed equilibrium is elastic: a body with a relaxation state has none."""
        if getattr(self, "hereditary", None) is not None:
            raise ConfigError(f"fem_static.{what}: this body relaxes (hereditary viscoelasticity), so a force has no "
                              "single equilibrium; build it with an elastic material (relax_fraction 0) or "
                              "viscoelastic='relaxed'")

    def compliance_block(self, nodes, axis: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(W, u0) of free ``nodes`` (m,): W (3m, 3m) m/N the displacement of their dofs per unit force
        on them (cached compliance columns), u0 (3m,) m their displacement under the Dirichlet
        targets and gravity alone. A contact solved on them needs no solve of the whole body.
        ``axis`` (0, 1 or 2): only that axis, W (m, m) and u0 (m,), from single-axis columns (a third
        of the back-substitutions; for loads along that axis, :meth:`apply_axial_forces`)."""
        self._require_elastic("compliance_block")
        idx = self._as_indices(nodes, "compliance_block nodes")
        if np.any(self.fixed[idx]):
            raise ConfigError(f"fem_static.compliance_block: nodes {idx[self.fixed[idx]][:5].tolist()} are fixed; "
                              "pass free nodes only")
        comp = self.compliance()
        u0 = self._base_displacement()
        if axis is not None:
            ax = validate.integer(axis, "fem_static.compliance_block axis", lo=0, hi=2, fix="0, 1 or 2 (2 = z)")
            return comp.axis_block(idx, ax), u0[3 * idx + ax].copy()
        dofs = (3 * idx[:, None] + np.arange(3)).reshape(-1)
        return comp.block(idx, comp.slots(idx)), u0[dofs].copy()

    def apply_axial_forces(self, nodes, forces, axis: int) -> np.ndarray:
        """:meth:`apply_nodal_forces` for forces (m,) N along ``axis`` only, from single-axis compliance
        columns (:meth:`compliance_block` with ``axis``). Returns the positions (N,3) m (a copy)."""
        self._require_elastic("apply_axial_forces")
        ax = validate.integer(axis, "fem_static.apply_axial_forces axis", lo=0, hi=2, fix="0, 1 or 2 (2 = z)")
        idx = self._as_indices(nodes, "apply_axial_forces nodes")
        f = np.asarray(forces, dtype=np.float64)
        if f.shape != (len(idx),) or not np.all(np.isfinite(f)):
            raise ConfigError(f"fem_static.apply_axial_forces: forces must be a finite ({len(idx)},) array (N), "
                              f"got shape {f.shape}")
        if np.any(self.fixed[idx]):
            raise ConfigError("fem_static.apply_axial_forces: a fixed node takes no force; pass free nodes only")
        comp = self.compliance()
        u = self._base_displacement().copy()
        if len(idx):
            comp.axis_response(comp.axis_slots(idx, ax), f, ax, u)
        full = np.zeros((len(idx), 3))
        full[:, ax] = f
        return self._set_static_state(u, idx, full)

    def apply_nodal_forces(self, nodes, forces) -> np.ndarray:
        """Set the equilibrium under ``forces`` (m,3) N on free ``nodes`` (m,) alone, plus the Dirichlet
        targets and gravity, from the cached compliance columns (no full solve): ``positions``
        updated, velocities zeroed, ``integrated_external_forces`` the applied forces. Returns the
        positions (N,3) m (a copy)."""
        self._require_elastic("apply_nodal_forces")
        idx = self._as_indices(nodes, "apply_nodal_forces nodes")
        f = np.asarray(forces, dtype=np.float64)
        if f.shape != (len(idx), 3) or not np.all(np.isfinite(f)):
            raise ConfigError(f"fem_static.apply_nodal_forces: forces must be a finite ({len(idx)}, 3) array (N), "
                              f"got shape {f.shape}")
        if np.any(self.fixed[idx]):
            raise ConfigError("fem_static.apply_nodal_forces: a fixed node takes no force; pass free nodes only")
        comp = self.compliance()
        u = self._base_displacement().copy()
        if len(idx):
            comp.response(comp.slots(idx), f, u)
        return self._set_static_state(u, idx, f)

    def _set_static_state(self, u: np.ndarray, idx: np.ndarray, f: np.ndarray) -> np.ndarray:
        """positions = rest + ``u`` (3N,) m at rest (velocities zeroed), forces ``f`` (m,3) N on ``idx``."""
        self.positions = self.rest_positions + u.reshape(-1, 3)
        self.velocities = np.zeros_like(self.positions)
        self.integrated_external_forces[:] = 0.0
        self.integrated_external_forces[idx] = f
        self.external_forces = np.zeros_like(self.positions)
        self.external_forces[idx] = f
        return self.positions.copy()

    def _step_state_arrays(self) -> list:
        return [self._hist, self._u_step] if hasattr(self, "_hist") else []

    def _reset_state(self) -> None:
        super()._reset_state()
        self.last_loaded = 0
        if hasattr(self, "_hist"):
            self._hist[:] = 0.0
            self._u_step[:] = 0.0

    def describe(self) -> dict:
        out = super().describe()
        cached = 0 if self._comp is None else int(np.count_nonzero(self._comp.node_in >= 0))
        out.update(cache_mb=self.cache_mb, cached_columns=cached, fixed_dofs=int(self.fixed_dofs.sum()))
        return out
