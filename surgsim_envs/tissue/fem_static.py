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

Choices: small strain (no corotation: a rotating element would change K and void the cached
columns; the indentation depths of the benchmark are <= 0.3 R); viscoelastic materials give their
long-term (relaxed) equilibrium, moduli x (1 - relax_fraction), as ``fem.static_solve`` does; the
symmetry planes of a quarter model may be held per dof with ``fixed_dofs``. See
docs/models/fem_static.md.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
from numba import njit

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError, TissueUnstableError
from surgsim_envs.tissue import fem_assembly as asm
from surgsim_envs.tissue.compliance import DEFAULT_CACHE_MB, SOLVERS, CondensedCompliance
from surgsim_envs.tissue.fem import TetFEMModel
from surgsim_envs.tissue.guard import StabilityGuard


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
def commit_positions(u, rest, positions, velocities, dt):
    """positions = rest + u (u (3N,) m), velocities = finite difference over ``dt`` s, in place."""
    for i in range(rest.shape[0]):
        for j in range(3):
            x = rest[i, j] + u[3 * i + j]
            velocities[i, j] = (x - positions[i, j]) / dt
            positions[i, j] = x


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
    """

    name: ClassVar[str] = "fem_static"
    summary: ClassVar[str] = ("quasi-static small-strain tet FEM (ANP): prefactored sparse LU, contact condensed "
                              "on cached compliance columns (SOFA precomputed compliance)")
    integrators: ClassVar[tuple[str, ...]] = ("quasi_static",)
    auto_pair = None
    default_integrator = None
    capabilities = frozenset({"forces", "unstructured_mesh", "implicit_contact", "quasi_static", "static_solve",
                              "subsurface_stiffness", "condensed_compliance"})
    material_fields = ("young", "poisson", "density")

    def __init__(self, volume, material="liver", *, formulation: str = "anp", fixed_dofs=None,
                 cache_mb: float = DEFAULT_CACHE_MB, solver: str = "superlu", precompute=None, integrator: str | None = None,
                 corotational: bool = False, **base_kwargs):
        if corotational:
            raise ConfigError("fem_static is small-strain only (corotational=False): its factorised stiffness and "
                              "cached compliance are valid for one K; use model 'fem' for large rotations")
        for key in ("stiffness_damping", "rotation_iters", "cg_tol", "threads", "preconditioner"):
            if key in base_kwargs:
                raise ConfigError(f"fem_static has no option {key!r} (it has no dynamic integrator); options: "
                                  "formulation, fixed_dofs, cache_mb, solver, fixed, gravity, region_materials")
        self.cache_mb = validate.positive(cache_mb, "fem_static: cache_mb", unit="MB",
                                          fix="the memory of cached compliance rows, e.g. 256")
        self.solver = validate.choice(solver, "fem_static: solver", SOLVERS,
                                      fix="'superlu', 'pardiso' (needs pypardiso) or 'auto'")
        self._comp: CondensedCompliance | None = None
        if base_kwargs.get("guard") is None:
            # a linear solve with a factorised SPD stiffness cannot diverge: an inverted element means
            # the load is beyond small strain (an accuracy limit, see inverted_elements()), not an
            # instability, so the guard checks only non-finite states and speeds
            # (and its energy check, which evaluates the elastic energy, runs every 100 steps)
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
        self.last_loaded = 0
        self._loaded_buf = np.zeros(n, dtype=np.int64)
        self._zero_kc = np.zeros(n)
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
        if self._visco:                      # quasi-static: relaxed moduli, E (1 - relax_fraction)
            r = 1.0 - self.relax_g
            self.mu, self.lam, self._kappa_el = self.mu * r, self.lam * r, self._kappa_el * r
            self._ke = self._ke * r[:, None, None]
            self.kappa_node = asm.nodal_average(self.tets, self.tet_volume, self._kappa_el, self.n_nodes)
            self._k_rest = self._assemble_stiffness(None)
            self._visco = False
        self._comp = None
        self._comp_version = -1
        self._u0_stale = True

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
        comp = self.compliance()
        if self._u0_stale:
            n = self.n_nodes
            uc = np.zeros(3 * n)
            fx = self.fixed
            uc.reshape(-1, 3)[fx] = (self.fixed_targets[fx] - self.rest_positions[fx])
            load = (self.masses[:, None] * self.gravity[None, :]).ravel() - self._k_rest @ uc
            u = comp.solve(np.where(comp.free, load, 0.0)) if (np.any(uc) or np.any(self.gravity)) else np.zeros(3 * n)
            self._u0 = u + uc
            self._u0_stale = False
        return self._u0

    # ------------------------------------------------------------------------------------------
    # Step: equations (2)-(3) of the module docstring
    def _advance(self, dt: float, forces: np.ndarray, stiffness) -> None:
        n = self.n_nodes
        comp = self.compliance()
        u0 = self._base_displacement()
        held = self.fixed
        if stiffness is not None:
            kc = np.asarray(stiffness, dtype=np.float64)
            if kc.shape != (n,) or np.any(kc < 0):
                raise ConfigError(f"fem_static: stiffness must be (N,) >= 0 N/m, got shape {kc.shape}")
        else:
            kc = None
        loaded = self._loaded_buf[:find_loaded(forces, self._zero_kc if kc is None else kc, held, self._loaded_buf)]
        x_prev = self.positions
        u = u0.copy()
        self.last_loaded = len(loaded)
        if len(loaded):
            slots = comp.slots(loaded)
            w = comp.block(loaded, slots)
            f_a = forces[loaded].reshape(-1)
            un_a = (x_prev[loaded] - self.rest_positions[loaded]).reshape(-1)
            dofs = (3 * loaded[:, None] + np.arange(3)).reshape(-1)
            if kc is not None:
                k_a = np.repeat(kc[loaded], 3)
                rhs = u0[dofs] + w @ (f_a + k_a * un_a)
                u_a = np.linalg.solve(np.eye(len(dofs)) + w * k_a[None, :], rhs)
                g = f_a - k_a * (u_a - un_a)
            else:
                g = f_a
            comp.response(slots, g.reshape(-1, 3), u)
            self.integrated_external_forces[loaded] = g.reshape(-1, 3)
        commit_positions(u, self.rest_positions, self.positions, self.velocities, dt)
        self.external_forces = forces

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
        """(N,3) N elastic nodal forces -K u (no inertia, no viscous term: quasi-static)."""
        return self.elastic_forces()

    # ------------------------------------------------------------------------------------------
    def static_solve(self, forces=None, stiffness=None, **kwargs) -> np.ndarray:
        """Equilibrium positions (N,3) m under ``forces`` (N,3) N (default: the last ones) and the
        Dirichlet targets: one full back-substitution (no condensation). Updates ``positions``
        (velocities zeroed) and returns a copy. ``stiffness`` is not accepted (no contact state)."""
        if stiffness is not None:
            raise ConfigError("fem_static.static_solve takes no contact stiffness; use step(dt, forces, stiffness)")
        if kwargs:
            raise ConfigError(f"fem_static.static_solve has no options {sorted(kwargs)}")
        f = self.external_forces if forces is None else np.asarray(forces, dtype=np.float64)
        if f.shape != self.positions.shape or not np.all(np.isfinite(f)):
            raise ConfigError(f"forces must be a finite array of shape {self.positions.shape}, got {f.shape}")
        comp = self.compliance()
        u = self._base_displacement() + comp.solve(np.where(comp.free, f.reshape(-1), 0.0))
        self.positions = self.rest_positions + u.reshape(-1, 3)
        self.velocities = np.zeros_like(self.positions)
        return self.positions.copy()

    def _require_elastic(self, what: str) -> None:
        """The condensed equilibrium is elastic: a body with a relaxation state has none."""
        if getattr(self, "hereditary", None) is not None:
            raise ConfigError(f"fem_static.{what}: this body relaxes (hereditary viscoelasticity), so a force has no "
                              "single equilibrium; build it with an elastic material (relax_fraction 0) or "
                              "viscoelastic='relaxed'")

    def compliance_block(self, nodes) -> tuple[np.ndarray, np.ndarray]:
        """(W, u0) of free ``nodes`` (m,): W (3m, 3m) m/N the displacement of their dofs per unit force
        on them (cached compliance columns), u0 (3m,) m their displacement under the Dirichlet
        targets and gravity alone. A contact solved on them needs no solve of the whole body."""
        self._require_elastic("compliance_block")
        idx = self._as_indices(nodes, "compliance_block nodes")
        if np.any(self.fixed[idx]):
            raise ConfigError(f"fem_static.compliance_block: nodes {idx[self.fixed[idx]][:5].tolist()} are fixed; "
                              "pass free nodes only")
        comp = self.compliance()
        u0 = self._base_displacement()
        dofs = (3 * idx[:, None] + np.arange(3)).reshape(-1)
        return comp.block(idx, comp.slots(idx)), u0[dofs].copy()

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
        self.positions = self.rest_positions + u.reshape(-1, 3)
        self.velocities = np.zeros_like(self.positions)
        self.integrated_external_forces[:] = 0.0
        self.integrated_external_forces[idx] = f
        self.external_forces = np.zeros_like(self.positions)
        self.external_forces[idx] = f
        return self.positions.copy()

    def _reset_state(self) -> None:
        super()._reset_state()
        self.last_loaded = 0

    def describe(self) -> dict:
        out = super().describe()
        cached = 0 if self._comp is None else int(np.count_nonzero(self._comp.node_in >= 0))
        out.update(cache_mb=self.cache_mb, cached_columns=cached, fixed_dofs=int(self.fixed_dofs.sum()))
        return out
