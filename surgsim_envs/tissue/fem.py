"""Linear / corotational tetrahedral FEM: the "basic model" of Vandewalle et al. 2003 (section 2.1).

Linear 4-node tets, Hooke's law ``sigma = D eps`` (paper eq. 2), ``eps = B u`` (eq. 3),
``K_e = B^T D B V``; the global system ``K U = R`` with Dirichlet nodes. Additions for
interactive surgery simulation:

* corotational option (``corotational=True``, default): each tet's rotation R (polar
  decomposition of F) is factored out, ``f_e = -R K_e (R^T x - X)``, so large rigid rotations
  produce no spurious forces;
* locking-free volumetric term (``formulation="anp"``, default): averaged nodal pressure of
  Bonet & Burton (1998), linearised: deviatoric stress per tet, pressure from the volume change
  averaged over each node's incident tets. ``formulation="standard"`` is plain ``B^T D B V``
  (locks at nu -> 0.5);
* integrators: ``"implicit"`` (backward Euler, one linear solve per step; sparse LU of
  ``M + dt C + dt^2 K`` for the linear model, matrix-free PCG with the warped stiffness for the
  corotational one, preconditioned by Jacobi or, for nearly incompressible ANP materials, by the
  "pressure" preconditioner: the exact inverse (Woodbury, cached sparse LU of an N x N pressure
  Schur complement) of the diagonal part plus the rest-state ANP volumetric term) and ``"symplectic"`` (semi-implicit Euler, numba kernels); the default
  ``"auto"`` runs symplectic while dt <= stable_dt(), else implicit (TissueModel.choose_integrator);
* viscoelasticity (material ``relax_fraction`` g / ``relax_time`` tau): a standard-linear-solid
  (one-term Prony) branch per element on the corotated stress, :mod:`fem_viscous`; a held strain
  relaxes the stress to (1 - g) of its instantaneous value with time constant tau;
* damping ``C = alpha M + beta K`` with alpha = material ``damping`` (1/s, per element) and
  beta = ``stiffness_damping`` (s, default ``material.extra.get("stiffness_damping", 0)``).

Units: m, kg, s, N, Pa. See docs/models/fem.md for equations, stable region and timings.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import numba

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError, StaticSolveError
from surgsim_envs.tissue import fem_assembly as asm
from surgsim_envs.tissue import fem_kernels as kern
from surgsim_envs.tissue import fem_viscous as visc
from surgsim_envs.tissue.base import TissueModel

FORMULATIONS = ("anp", "standard")
PRECONDITIONERS = ("auto", "jacobi", "pressure")
#: ``preconditioner="auto"`` uses "pressure" when the largest bulk/shear ratio kappa/mu of the
#: elements exceeds this (nu > ~0.46; silicone nu = 0.499: 500, fat nu = 0.49: 50, liver/skin nu = 0.45: 9.7)
PRESSURE_PRECONDITIONER_RATIO = 12.0


class TetFEMModel(TissueModel):
    """Linear tetrahedral FEM, optionally corotational, with a locking-free (ANP) option.

    Parameters (besides those of :class:`TissueModel`)
    ----------
    corotational: remove per-element rotations (large-rotation capable). Default True.
    formulation: ``"anp"`` (averaged nodal pressure, locking-free; default) or ``"standard"``.
    stiffness_damping: Rayleigh stiffness coefficient beta (s), >= 0.
    rotation_iters: Newton iterations of the polar decomposition per step (warm-started; 1 is
        enough at interactive dt, the rotation keeps converging over the following steps).
    cg_tol: relative residual of the implicit corotational solve.
    preconditioner: of that solve: ``"jacobi"`` (nodal diagonal), ``"pressure"`` (ANP only: diagonal +
        rest-state volumetric term, inverted exactly through a cached N x N sparse LU; few iterations
        at nu -> 0.5) or ``"auto"`` (default: "pressure" for ANP when max kappa/mu >
        ``PRESSURE_PRECONDITIONER_RATIO``, else "jacobi").
    threads: numba threads for the element loops (1: single-thread kernels, the default, robust on
        a shared machine; >= 2: ``prange`` passes, deterministic and bitwise independent of the
        thread count; capped at ``numba.config.NUMBA_NUM_THREADS``). Parallel passes wait for
        every thread at each pass, so only use them when the cores are not busy with other work.
    """

    name = "fem"
    summary = "Linear tetrahedral FEM (Vandewalle et al. 2003 basic model): corotational, locking-free ANP, implicit/symplectic"
    integrators = ("implicit", "symplectic")
    auto_pair = ("symplectic", "implicit")
    default_integrator = "auto"
    capabilities = frozenset({"forces", "unstructured_mesh", "implicit_contact", "viscoelastic", "static_solve",
                              "subsurface_stiffness"})
    material_fields = ("young", "poisson", "density", "damping", "relax_fraction", "relax_time")

    def __init__(self, volume, material="liver", *, integrator=None, corotational: bool = True,
                 formulation: str = "anp", stiffness_damping: float | None = None,
                 rotation_iters: int = 1, cg_tol: float = 1e-6, threads: int = 1,
                 preconditioner: str = "auto", **base_kwargs):
        if not isinstance(corotational, (bool, np.bool_)):
            raise ConfigError(f"corotational must be True or False, got {corotational!r}")
        if formulation not in FORMULATIONS:
            raise ConfigError(f"formulation must be one of {list(FORMULATIONS)}, got {formulation!r}; "
                              "'anp' (averaged nodal pressure) avoids volumetric locking for nu near 0.5")
        if preconditioner not in PRECONDITIONERS:
            raise ConfigError(f"preconditioner must be one of {list(PRECONDITIONERS)}, got {preconditioner!r}")
        if preconditioner == "pressure" and formulation != "anp":
            raise ConfigError("preconditioner='pressure' needs formulation='anp'; use 'jacobi' or 'auto'")
        super().__init__(volume, material, integrator=integrator, **base_kwargs)
        if stiffness_damping is None:
            stiffness_damping = float(self.material.extra.get("stiffness_damping", 0.0))
        validate.non_negative(stiffness_damping, "stiffness_damping", unit="s", fix="the Rayleigh beta; 0 = none")
        validate.real(cg_tol, "cg_tol", lo=0.0, hi=1.0, lo_open=True, hi_open=True,
                      fix="it is the relative CG residual, e.g. 1e-6")
        validate.integer(rotation_iters, "rotation_iters", lo=1, fix="give an integer >= 1")
        validate.integer(threads, "threads", lo=1, fix="1 = single-thread kernels")
        self.threads = min(int(threads), int(numba.config.NUMBA_NUM_THREADS))
        self._parallel = self.threads > 1
        self.corotational = bool(corotational)
        self.formulation = formulation
        self.stiffness_damping = float(stiffness_damping)
        self.rotation_iters = int(rotation_iters)
        self.cg_tol = float(cg_tol)
        self.last_cg_iterations = 0
        self._setup()
        if preconditioner == "auto":
            ratio = float(np.max((self.lam + 2.0 * self.mu / 3.0) / self.mu))
            preconditioner = "pressure" if (self._anp and ratio > PRESSURE_PRECONDITIONER_RATIO) else "jacobi"
        self.preconditioner = preconditioner

    # ------------------------------------------------------------------------------------------
    # Precomputation
    def _setup(self) -> None:
        vol = self.volume
        n = vol.n_nodes
        self.tets = np.ascontiguousarray(vol.tets, dtype=np.int64)
        self.grads, self.tet_volume, self.dm_inv = asm.shape_gradients(self.rest_positions, self.tets)
        self.node_volume = asm.nodal_volumes(self.tets, self.tet_volume, n)
        t = len(self.tets)
        self._rots = np.ascontiguousarray(np.broadcast_to(np.eye(3), (t, 3, 3)).copy())
        self._work = kern.make_work(self.tets, n)
        self._ybuf = np.zeros((n, 3))
        self._fbuf = np.zeros((n, 3))
        self._v_prev = None       # velocity before the last implicit step (CG warm start 2 v - v_prev)
        # viscoelastic branch state (fem_viscous): h (T,3,3) Pa, sigma0 at the last commit, pending step
        self._h = np.zeros((t, 3, 3))
        self._sig_prev = np.zeros((t, 3, 3))
        self._trv = np.zeros(t)
        self._pnode = np.zeros(n)
        self._pending_dt = 0.0
        self._setup_material()

    def _on_material_changed(self, name: str) -> None:
        """Re-derive moduli, element stiffness, damping and viscoelastic coefficients; drop the
        cached factorisations, preconditioner and critical dt (contract v2 ``scale_material``)."""
        self._setup_material()

    def _setup_material(self) -> None:
        """Everything derived from the per-element material fields (called at build and by
        :meth:`scale_material` / :meth:`set_field`)."""
        n = self.n_nodes
        young, poisson = self.fields["young"], self.fields["poisson"]
        bad = np.flatnonzero((young <= 0) | (poisson >= 0.5) | (poisson <= -1))
        if len(bad):
            raise ConfigError(f"linear FEM needs E > 0 and -1 < nu < 0.5; element {bad[0]} has E={young[bad[0]]!r} Pa, "
                              f"nu={poisson[bad[0]]!r}. Use nu <= 0.499 for nearly incompressible tissue")
        g, tau = self.fields["relax_fraction"], self.fields["relax_time"]
        bad = np.flatnonzero((g < 0) | (g >= 1) | (tau <= 0))
        if len(bad):
            raise ConfigError(f"FEM viscoelasticity needs 0 <= relax_fraction < 1 and relax_time > 0 s; element "
                              f"{bad[0]} has relax_fraction={g[bad[0]]!r}, relax_time={tau[bad[0]]!r}")
        self.relax_g, self.relax_tau = g.copy(), tau.copy()
        self._visco = bool(np.any(g > 0))
        self._visco_cache: dict = {}     # dt -> (decay, gamma, c, mu_c, lam_c, kappa_c, kdiag_c, kdev_c)
        self.mu, self.lam, kappa = asm.lame_parameters(young, poisson)
        self._kappa_el = kappa
        self.kappa_node = asm.nodal_average(self.tets, self.tet_volume, kappa, n)
        # mass-proportional damping per node: mass-weighted average of the element values
        md = np.zeros(n)
        np.add.at(md, self.tets.ravel(), np.repeat(self.fields["density"] * self.tet_volume / 4.0 * self.fields["damping"], 4))
        self.alpha_node = md / self.masses
        b = asm.b_matrices(self.grads)
        if self.formulation == "anp":
            self._ke = asm.element_stiffness(b, asm.deviatoric_d_matrices(young, poisson), self.tet_volume)
        else:
            self._ke = asm.element_stiffness(b, asm.d_matrices(young, poisson), self.tet_volume)
        self._k_rest = self._assemble_stiffness(None)
        self._kdiag_node = self._k_rest.diagonal().reshape(-1, 3).mean(axis=1)
        self._kdev_diag_node = None
        if self.formulation == "anp":   # diagonal of the deviatoric part (for the pressure preconditioner)
            self._kdev_diag_node = self._element_diagonal(self._ke)
        self._lin = None          # cached (dt, fixed mask, LU of A_ff) for the linear implicit step
        self._pre_refresh = False
        self._pre_base_iters = None
        self._pre = None          # cached pressure preconditioner (see _pressure_preconditioner)
        self._crit = None

    def _assemble_stiffness(self, rotations, scale=None) -> sp.csr_matrix:
        """Global (3N,3N) stiffness (N/m), warped by per-element ``rotations`` if given, with every
        element's moduli multiplied by ``scale`` (T,) if given (viscoelastic effective stiffness).
        At rest (no rotations) the sparsity pattern and the ANP volume operator are cached, so a
        material change (:meth:`scale_material`) re-assembles by a bincount, not a COO sort."""
        ke = self._ke if scale is None else self._ke * scale[:, None, None]
        if rotations is not None:
            k = asm.assemble(self.tets, asm.rotate_element_matrices(ke, rotations), self.n_nodes)
            if self.formulation == "anp":
                kappa = self.kappa_node if scale is None else self._scaled_kappa_node(scale)
                k = k + asm.anp_volumetric_matrix(self.tets, self.grads, self.tet_volume, kappa,
                                                  self.n_nodes, rotations)
            return k.tocsr()
        k = self._assemble_rest(ke)
        if self.formulation == "anp":
            kappa = self.kappa_node if scale is None else self._scaled_kappa_node(scale)
            bv, bvt = self._rest_volume_operator()
            k = k + (bvt @ sp.diags(kappa * self.node_volume) @ bv)
        return k.tocsr()

    def _assemble_rest(self, ke) -> sp.csr_matrix:
        """Sum of element matrices (T,12,12) into the cached CSR pattern of the mesh."""
        n3 = 3 * self.n_nodes
        if getattr(self, "_pattern", None) is None:
            dofs = asm.element_dofs(self.tets)
            key = np.repeat(dofs, 12, axis=1).ravel() * n3 + np.tile(dofs, (1, 12)).ravel()
            uniq, inv = np.unique(key, return_inverse=True)
            rows = uniq // n3
            indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=n3))])
            self._pattern = (inv, (uniq % n3).astype(np.int32), indptr.astype(np.int32), len(uniq))
        inv, indices, indptr, nnz = self._pattern
        data = np.bincount(inv, weights=ke.ravel(), minlength=nnz)
        return sp.csr_matrix((data, indices, indptr), shape=(n3, n3))

    def _rest_volume_operator(self):
        """Cached (Bv, Bv^T) of the rest-state ANP volume average (geometry only)."""
        if getattr(self, "_bv_rest", None) is None:
            bv = asm.anp_volume_operator(self.tets, self.grads, self.tet_volume, self.n_nodes).tocsr()
            self._bv_rest = (bv, bv.T.tocsr())
        return self._bv_rest

    def _element_diagonal(self, ke) -> np.ndarray:
        """(N,) mean over the three axes of the diagonal of the assembled element matrices."""
        d = np.bincount(asm.element_dofs(self.tets).ravel(), weights=np.diagonal(ke, axis1=1, axis2=2).ravel(),
                        minlength=3 * self.n_nodes)
        return d.reshape(-1, 3).mean(axis=1)

    def _scaled_kappa_node(self, scale) -> np.ndarray:
        return asm.nodal_average(self.tets, self.tet_volume, self._kappa_el * scale, self.n_nodes)

    def stiffness_matrix(self, relaxed: bool = False, clamp: bool = False) -> sp.csr_matrix:
        """Tangent stiffness ``-df/dx`` (scipy.sparse CSR, 3N x 3N, N/m, dof = 3 * node + axis),
        warped by the current element rotations (corotational) or at rest (linear).

        relaxed: long-term stiffness (viscoelastic branches relaxed: moduli x (1 - relax_fraction));
        else the instantaneous one. clamp: accepted for the common signature (the linear element
        stiffness is already positive semi-definite)."""
        rots = self._rots.copy() if self.corotational and np.any(self._rots != np.eye(3)) else None
        scale = (1.0 - self.relax_g) if (relaxed and self._visco) else None
        if rots is None and scale is None:
            return self._k_rest.copy()
        return self._assemble_stiffness(rots, scale)

    @property
    def _anp(self) -> bool:
        return self.formulation == "anp"

    # ------------------------------------------------------------------------------------------
    # Kernels wrappers
    def _set_threads(self) -> bool:
        """Numba thread count for the parallel kernels; returns whether to use them."""
        if self._parallel and numba.get_num_threads() != self.threads:
            numba.set_num_threads(self.threads)
        return self._parallel

    def _update_rotations(self, x, tol=None, max_iter=None) -> None:
        """Polar rotations at positions x: ``rotation_iters`` warm-started Newton steps while
        stepping (tol None), or iterate to ``tol`` rad (energies, static solves)."""
        if self.corotational:
            update = kern.update_rotations_parallel if self._set_threads() else kern.update_rotations
            if tol is None:
                update(x, self.tets, self.dm_inv, self._rots, self.rotation_iters, 1e-12)
            else:
                update(x, self.tets, self.dm_inv, self._rots, max_iter or 50, tol)

    def _stiffness_product(self, y, subtract_rest: bool, out=None, update_rotations: bool = False) -> np.ndarray:
        """R K R^T y [- R K X] (N); ``update_rotations``: first ``rotation_iters`` warm-started
        rotation steps at positions y, fused into the same element pass."""
        out = np.zeros_like(y) if out is None else out
        y = np.ascontiguousarray(y)
        iters = self.rotation_iters if (update_rotations and self.corotational) else 0
        product = kern.stiffness_product_parallel if self._set_threads() else kern.stiffness_product_serial
        product(y, self.tets, self.dm_inv, self.tet_volume, self.mu, self.lam, self._rots, subtract_rest, self._anp,
                self.kappa_node, self.node_volume, self._work, out, y, iters, 1e-12, True)
        return out

    def elastic_forces(self, positions=None) -> np.ndarray:
        """(N,3) elastic nodal forces (N) at ``positions`` (default: current), no damping."""
        x = self.positions if positions is None else np.asarray(positions, dtype=np.float64)
        if x.shape != self.positions.shape:
            raise ConfigError(f"positions must have shape {self.positions.shape}, got {x.shape}")
        self._update_rotations(x, tol=1e-10)
        f = -self._stiffness_product(x, True)
        if self._visco:
            self._add_branch_forces(f, self._branch_excess(x))
        return f

    def internal_forces(self) -> np.ndarray:
        """Elastic (with the viscoelastic branches) + viscous (Rayleigh beta K v and
        mass-proportional alpha M v) nodal forces (N)."""
        self._update_rotations(self.positions, tol=1e-10)
        y = self.positions + self.stiffness_damping * self.velocities
        f = -self._stiffness_product(y, True)
        if self._visco:
            self._add_branch_forces(f, self._branch_excess(self.positions))
        return f - (self.alpha_node * self.masses)[:, None] * self.velocities

    # ------------------------------------------------------------------------------------------
    # Viscoelastic branches (fem_viscous)
    def _instant_stress(self, x, out) -> np.ndarray:
        """Corotated instantaneous stress sigma0 (T,3,3) Pa at x with the current rotations."""
        visc.corotated_stress(np.ascontiguousarray(x), self.tets, self.dm_inv, self.tet_volume, self._rots,
                              self.mu, self.lam, self._anp, self.kappa_node, self.node_volume, self._trv,
                              self._pnode, out)
        return out

    def _branch_state_at(self, sig0) -> np.ndarray:
        """h (T,3,3) Pa brought from the last commit to a state with instantaneous stress sig0."""
        decay, gamma = self._coeffs(self._pending_dt)[:2]
        return decay[:, None, None] * self._h + gamma[:, None, None] * (sig0 - self._sig_prev)

    def _branch_excess(self, x) -> np.ndarray:
        """g (h - sigma0) (T,3,3) Pa at x: the stress to add to the instantaneous elastic one."""
        sig0 = self._instant_stress(x, np.empty_like(self._h))
        return self.relax_g[:, None, None] * (self._branch_state_at(sig0) - sig0)

    def _add_branch_forces(self, f, stress) -> None:
        visc.add_stress_forces(self.tets, self.grads, self.tet_volume, self._rots, np.ascontiguousarray(stress), f)

    def _branch_work(self) -> tuple:
        """Work buffers of the fused explicit step (:func:`fem_viscous.symplectic_step`): the strain at
        x_n with the rotations before the step (T,6), its nodal volume change (N,), those rotations (T,3,3)."""
        w = getattr(self, "_branch_buffers", None)
        if w is None or w[0].shape[0] != len(self.tets):
            t = len(self.tets)
            w = self._branch_buffers = (np.zeros((t, 6)), np.zeros(self.n_nodes), np.zeros((t, 3, 3)))
        return w

    def _coeffs(self, h: float):
        """Per-dt cache: (decay, gamma, c, mu_c, lam_c, kappa_node_c, kdiag_c, kdev_c), with c = 1 - g + g gamma
        the effective modulus factor of an implicit step of length h."""
        hit = self._visco_cache.get(h)
        if hit is not None:
            return hit
        decay, gamma = visc.branch_coefficients(h, self.relax_tau)
        c = 1.0 - self.relax_g + self.relax_g * gamma
        out = (decay, gamma, c)
        if h > 0 and self._visco:
            k = self._assemble_stiffness(None, c)
            kdev = None
            if self._anp:
                kdev = self._element_diagonal(self._ke * c[:, None, None])
            out = out + (self.mu * c, self.lam * c, self._scaled_kappa_node(c),
                         k.diagonal().reshape(-1, 3).mean(axis=1), kdev, k)
        if len(self._visco_cache) > 8:
            self._visco_cache.clear()
        self._visco_cache[h] = out
        return out

    def elastic_energy(self) -> float:
        """Stored energy (J) at the current positions. The rotations are first iterated (same
        pass) until the Newton step is below 1e-6 rad: the energy is stationary in R at the polar
        rotation, so its relative error is O(1e-12)."""
        energy = kern.elastic_energy_parallel if self._set_threads() else kern.elastic_energy
        return float(energy(self.positions, self.tets, self.dm_inv, self.tet_volume, self.mu, self.lam, self._rots,
                            self._anp, self.kappa_node, self.node_volume, 50 if self.corotational else 0, 1e-6,
                            self._work))

    def inverted_elements(self) -> int:
        """Tets with det F <= 0 at the current positions."""
        return int(kern.count_inverted(self.positions, self.tets))

    def element_stress(self) -> np.ndarray:
        """(T,3,3) Cauchy stress (Pa) per tet (linear/corotated: R sigma R^T), incl. ANP pressure
        and the viscoelastic branches."""
        self._update_rotations(self.positions, tol=1e-10)
        if self._visco:
            sig = self._instant_stress(self.positions, np.empty_like(self._h))
            sig = sig + self.relax_g[:, None, None] * (self._branch_state_at(sig) - sig)
            return np.einsum("tij,tjk,tlk->til", self._rots, sig, self._rots)
        x = self.positions
        ds = np.stack([x[self.tets[:, k]] - x[self.tets[:, 0]] for k in (1, 2, 3)], axis=2)
        g = np.einsum("tji,tjk,tkl->til", self._rots, ds, self.dm_inv) - np.eye(3)
        eps = 0.5 * (g + g.transpose(0, 2, 1))
        tr = np.trace(eps, axis1=1, axis2=2)
        if self._anp:
            theta = np.zeros(self.n_nodes)
            np.add.at(theta, self.tets.ravel(), np.repeat(0.25 * self.tet_volume * tr, 4))
            p_node = self.kappa_node * theta / self.node_volume
            p = p_node[self.tets].mean(axis=1)
            sig = 2.0 * self.mu[:, None, None] * (eps - tr[:, None, None] / 3.0 * np.eye(3)) + p[:, None, None] * np.eye(3)
        else:
            sig = 2.0 * self.mu[:, None, None] * eps + (self.lam * tr)[:, None, None] * np.eye(3)
        return np.einsum("tij,tjk,tlk->til", self._rots, sig, self._rots)

    # ------------------------------------------------------------------------------------------
    # Stability
    def critical_dt(self, method: str = "spectral") -> float:
        """Largest stable dt (s) of the symplectic integrator (raw estimate, no safety factor:
        :meth:`stable_dt` applies the one factor DT_SAFETY).

        ``"spectral"`` (default): 2 / omega_max with omega_max^2 the largest eigenvalue of
        M^-1 K (rest stiffness, Lanczos, cached), reduced for stiffness damping beta by
        ``sqrt(1 + z^2) - z``, z = beta omega / 2. ``"geometric"``: min over tets of the
        inscribed-sphere diameter 2 r_e over the dilatational wave speed sqrt((lambda + 2 mu)/rho)
        (cheap, usually within a factor ~2 of the spectral value; see docs/models/fem.md).
        """
        if method == "geometric":
            return self._geometric_dt()
        if method != "spectral":
            raise ConfigError(f"critical_dt method must be 'spectral' or 'geometric', got {method!r}")
        if self._crit is None:
            self._crit = self._spectral_dt()
        return self._crit

    def _max_omega(self) -> float:
        minv = 1.0 / np.sqrt(np.repeat(self.masses, 3))
        a = sp.diags(minv) @ self._k_rest @ sp.diags(minv)
        try:
            v0 = np.cos(np.arange(a.shape[0]) * 0.7071)   # fixed start vector: reproducible dt
            lam = spla.eigsh(a, k=1, which="LA", return_eigenvectors=False, tol=1e-4, maxiter=5000, v0=v0)[0]
        except spla.ArpackNoConvergence as exc:  # pragma: no cover - fall back on the Gershgorin bound
            lam = float(np.max(np.abs(a).sum(axis=1)))
            del exc
        return math.sqrt(max(float(lam), 1e-300))

    def _spectral_dt(self) -> float:
        omega = self._max_omega()
        z = 0.5 * self.stiffness_damping * omega
        return (2.0 / omega) * (math.sqrt(1.0 + z * z) - z)

    def _geometric_dt(self) -> float:
        x = self.rest_positions
        t = self.tets
        faces = ((1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2))
        area = np.zeros(len(t))
        for a, b, c in faces:
            area += 0.5 * np.linalg.norm(np.cross(x[t[:, b]] - x[t[:, a]], x[t[:, c]] - x[t[:, a]]), axis=1)
        r_in = 3.0 * self.tet_volume / area
        c = np.sqrt((self.lam + 2.0 * self.mu) / self.fields["density"])
        return float(np.min(2.0 * r_in / c))

    # ------------------------------------------------------------------------------------------
    # Stepping
    def _advance(self, dt: float, forces: np.ndarray, stiffness) -> None:
        forces = np.ascontiguousarray(forces, dtype=np.float64)
        kc = None
        if stiffness is not None:   # validated for both integrators (used by the implicit one)
            kc = np.asarray(stiffness, dtype=np.float64).reshape(-1)
            if kc.shape != (self.n_nodes,) or not np.all(np.isfinite(kc)) or np.any(kc < 0):
                raise ConfigError(f"stiffness must be a finite (N,)={self.n_nodes} array of >= 0 N/m, got shape {kc.shape}")
            if not kc.any():
                kc = None
        implicit = self.active_integrator != "symplectic"
        parallel = self._set_threads()
        if self._visco and not implicit and not parallel:
            # branches committed at x_n and the elastic forces in the same element passes (fem_viscous)
            decay, gamma = self._coeffs(self._pending_dt)[:2]
            visc.symplectic_step(self.positions, self.velocities, forces, self.masses, self.alpha_node, self.gravity,
                                 self.fixed, dt, self.stiffness_damping, self.corotational, self.rotation_iters, 1e-12,
                                 self.tets, self.dm_inv, self.tet_volume, self.mu, self.lam, self._rots,
                                 self._anp, self.kappa_node, self.node_volume, self._work, self._ybuf,
                                 self._fbuf, self.relax_g, decay, gamma, self._h, self._sig_prev,
                                 *self._branch_work())
            self._pending_dt = dt
            return
        if self._visco:
            # branches committed at x_n; their extra stress enters as constant corotated element stress
            decay, gamma = self._coeffs(self._pending_dt)[:2]
            if implicit:   # end-of-step stress c sigma0_{n+1} + g (decay h_n - gamma sigma0_n)
                keep, take = self._coeffs(dt)[:2]
            else:          # stress at x_n: (1 - g) sigma0_n + g h_n
                keep = take = self._coeffs(0.0)[0]     # ones
            eps, theta, _ = self._branch_work()
            forces = forces.copy()
            visc.commit_forces(self.positions, self.tets, self.dm_inv, self.tet_volume, self._rots, self.mu, self.lam,
                               self._anp, self.kappa_node, self.node_volume, self.relax_g, decay, gamma, self._h,
                               self._sig_prev, keep, take, eps, theta, forces)
            self._pending_dt = dt
        if not implicit:
            step = kern.symplectic_step_parallel if parallel else kern.symplectic_step
            step(self.positions, self.velocities, forces, self.masses, self.alpha_node, self.gravity, self.fixed, dt,
                 self.stiffness_damping, self.corotational, self.rotation_iters, 1e-12, self.tets, self.dm_inv,
                 self.tet_volume, self.mu, self.lam, self._rots, self._anp, self.kappa_node, self.node_volume,
                 self._work, self._ybuf, self._fbuf)
            return
        if self._visco:
            with self._effective_moduli(dt):
                self._implicit(dt, forces, kc)
        else:
            self._implicit(dt, forces, kc)
        if kc is not None:   # backward Euler integrated f_ext - kc (x_{n+1} - x_n) = f_ext - dt kc v_{n+1}
            free = ~self.fixed
            self.integrated_external_forces[free] -= (dt * kc[free])[:, None] * self.velocities[free]

    def _implicit(self, dt, forces, kc) -> None:
        if self.corotational:
            self._implicit_corotational(dt, forces, kc)
        else:
            self._implicit_linear(dt, forces, kc)

    def _effective_moduli(self, dt):
        """Context: moduli, stiffness and preconditioner diagonals scaled by c = 1 - g + g gamma(dt)
        (the viscoelastic element over an implicit step of dt) while the solve runs."""
        import contextlib

        @contextlib.contextmanager
        def swap():
            co = self._coeffs(dt)
            saved = (self.mu, self.lam, self.kappa_node, self._kdiag_node, self._kdev_diag_node, self._k_rest)
            self.mu, self.lam, self.kappa_node, self._kdiag_node, self._kdev_diag_node, self._k_rest = co[3:9]
            try:
                yield
            finally:
                self.mu, self.lam, self.kappa_node, self._kdiag_node, self._kdev_diag_node, self._k_rest = saved
        return swap()

    def _prescribed_velocity(self, dt: float) -> np.ndarray:
        vc = np.zeros_like(self.positions)
        fx = self.fixed
        vc[fx] = (self.fixed_targets[fx] - self.positions[fx]) / dt
        return vc

    def _implicit_linear(self, dt, forces, kc) -> None:
        free = ~self.fixed
        free3 = np.repeat(free, 3)
        c_k = self.stiffness_damping * dt + dt * dt
        mdiag = np.repeat(self.masses * (1.0 + self.alpha_node * dt), 3)
        lin = self._lin
        if lin is None or lin[0] != dt or not np.array_equal(lin[1], self.fixed):
            a = (sp.diags(mdiag) + c_k * self._k_rest).tocsr()
            a_ff = a[free3][:, free3].tocsc()
            lin = self._lin = (dt, self.fixed.copy(), spla.splu(a_ff))
        lu = lin[2]
        x, v = self.positions, self.velocities
        k = self._k_rest
        f_el = -(k @ (x - self.rest_positions).ravel())
        rhs = np.repeat(self.masses, 3) * v.ravel() + dt * (f_el + forces.ravel() + np.repeat(self.masses, 3) * np.tile(self.gravity, self.n_nodes))
        vc = self._prescribed_velocity(dt).ravel()
        if self.fixed.any():
            rhs = rhs - c_k * (k @ vc)
        rhs_f = rhs[free3]
        if kc is None:
            v_f = lu.solve(rhs_f)
        else:
            extra = dt * dt * np.repeat(kc, 3)[free3]
            a_ff = sp.diags(mdiag[free3] + extra) + c_k * k[free3][:, free3]
            pre = spla.LinearOperator(a_ff.shape, matvec=lu.solve)
            v_f, _ = spla.cg(a_ff, rhs_f, x0=lu.solve(rhs_f), M=pre, rtol=self.cg_tol, maxiter=200)
        vnew = vc.copy()
        vnew[free3] = v_f
        self.velocities = vnew.reshape(-1, 3)
        self.positions = self.positions + dt * self.velocities

    def _implicit_corotational(self, dt, forces, kc) -> None:
        x, v = self.positions, self.velocities
        c_k = self.stiffness_damping * dt + dt * dt
        diag = self.masses * (1.0 + self.alpha_node * dt)
        if kc is not None:
            diag = diag + dt * dt * kc
        f_el = -self._stiffness_product(x, True, update_rotations=True)
        rhs = self.masses[:, None] * v + dt * (f_el + forces + self.masses[:, None] * self.gravity[None, :])
        vc = self._prescribed_velocity(dt)
        free = ~self.fixed
        if vc.any():   # moving Dirichlet nodes
            rhs -= c_k * self._stiffness_product(vc, False)
        rhs[self.fixed] = 0.0
        guess = v if self._v_prev is None else 2.0 * v - self._v_prev
        self._v_prev = v.copy()
        sol = np.where(free[:, None], guess, 0.0)
        if self.preconditioner == "pressure":
            self.last_cg_iterations = self._pcg_pressure(rhs, sol, diag, c_k, dt, free)
        else:
            precond = diag + c_k * self._kdiag_node
            self.last_cg_iterations = int(kern.pcg_solve(
                rhs, sol, diag, c_k, precond, free, self.cg_tol, 10 * 3 * self.n_nodes, self.tets, self.dm_inv,
                self.tet_volume, self.mu, self.lam, self._rots, self._anp, self.kappa_node, self.node_volume,
                self._work, self._set_threads()))
        sol[self.fixed] = vc[self.fixed]
        self.velocities = sol
        self.positions = x + dt * sol

    def _pressure_preconditioner(self, dt, c_k):
        """Cached ``(dinv (N,), Bv_f (N,3N) sparse, LU of S)`` for z = P^-1 r with
        ``P = D + c_k Bv^T W Bv`` (free DOFs): D = M(1 + alpha dt) + c_k diag(K_dev) (nodal scalar),
        W = diag(kappa_a V_a), Bv the rest-state ANP volume operator with fixed-node columns removed.
        Woodbury: ``P^-1 = D^-1 - D^-1 Bv^T S^-1 Bv D^-1``, ``S = (c_k W)^-1 + Bv D^-1 Bv^T`` (N x N,
        SPD, a discrete pressure Poisson matrix). P is SPD, so CG stays a valid PCG under rotations
        and contact (which it ignores); rebuilt when dt, beta or the fixed set change, and with Bv
        warped by the current element rotations when the iteration count has grown past
        ``max(20, 2 x`` the count right after the last build) (large rotations, see _pcg_pressure)."""
        pre = self._pre
        if (pre is not None and pre[0] == (dt, c_k) and np.array_equal(pre[1], self.fixed)
                and not self._pre_refresh):
            return pre[2]
        rots = None
        if self._pre_refresh and self.corotational:   # the rotations have drifted: warp Bv with the current ones
            rots = self._rots.copy()
        self._pre_refresh = False
        self._pre_base_iters = None
        free3 = np.repeat(~self.fixed, 3).astype(np.float64)
        d = self.masses * (1.0 + self.alpha_node * dt) + c_k * self._kdev_diag_node
        dinv = 1.0 / d
        bv = asm.anp_volume_operator(self.tets, self.grads, self.tet_volume, self.n_nodes, rots) @ sp.diags(free3)
        bv = bv.tocsr()
        w = self.kappa_node * self.node_volume
        s = (sp.diags(1.0 / (c_k * w)) + bv @ sp.diags(np.repeat(dinv, 3)) @ bv.T).tocsc()
        lu = spla.splu(s, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options=dict(SymmetricMode=True))
        data = (dinv, bv, bv.T.tocsr(), lu)
        self._pre = ((dt, c_k), self.fixed.copy(), data)
        return data

    def _pcg_pressure(self, rhs, x, diag, c_k, dt, free) -> int:
        """PCG for ``(diag + c_k R K R^T) x = rhs`` on the free nodes with the pressure
        preconditioner; x (N,3) is the warm start (zero at fixed nodes), updated in place.
        Same stopping rule as :func:`fem_kernels.pcg_solve` (|r| <= cg_tol |rhs|). Returns the iterations."""
        dinv, bv, bvt, lu = self._pressure_preconditioner(dt, c_k)
        par = self._set_threads()
        args = (self.tets, self.dm_inv, self.tet_volume, self.mu, self.lam, self._rots, self._anp,
                self.kappa_node, self.node_volume, self._work, free)
        shape = x.shape

        def precondition(r):
            y = (dinv[:, None] * r).ravel()
            return (y - np.repeat(dinv, 3) * (bvt @ lu.solve(bv @ y))).reshape(shape)

        ap = np.empty(shape)
        kern.apply_system(x, diag, c_k, *args, ap, par)
        r = np.where(free[:, None], rhs - ap, 0.0)
        thresh = self.cg_tol ** 2 * max(float(np.vdot(rhs, rhs)), 1e-300)
        z = precondition(r)
        p = z.copy()
        rz = float(np.vdot(r, z))
        it = 0
        max_iter = 10 * 3 * self.n_nodes
        while it < max_iter and float(np.vdot(r, r)) > thresh:
            kern.apply_system(p, diag, c_k, *args, ap, par)
            pap = float(np.vdot(p, ap))
            if pap <= 0.0:
                break
            alpha = rz / pap
            x += alpha * p
            r -= alpha * ap
            z = precondition(r)
            rz_new = float(np.vdot(r, z))
            p *= rz_new / rz
            p += z
            rz = rz_new
            it += 1
        if self._pre_base_iters is None:
            self._pre_base_iters = it
        elif it > max(20, 2 * self._pre_base_iters):
            self._pre_refresh = True      # next step: rebuild P at the current rotations
        return it

    # ------------------------------------------------------------------------------------------
    # Static equilibrium
    def static_solve(self, forces: np.ndarray | None = None, *, max_iter: int = 50, tol: float = 1e-9) -> np.ndarray:
        """Equilibrium positions (N,3) m under external ``forces`` (N,3) N (+ gravity) and the
        current Dirichlet nodes/targets: solves K u = R (linear) or iterates with the warped
        stiffness R K R^T until the update is below ``tol`` times the body size (corotational;
        :class:`~surgsim_envs.errors.StaticSolveError` if ``max_iter`` iterations do not get there).
        Viscoelastic materials give the long-term (relaxed) equilibrium, moduli x (1 - relax_fraction),
        as the mass-spring model's static_solve; the branches are left fully relaxed there.
        Updates ``positions`` (velocities are zeroed) and returns a copy.
        """
        if not self._visco:
            return self._static_solve(forces, max_iter, tol)
        r = 1.0 - self.relax_g
        saved = (self.mu, self.lam, self.kappa_node, self._k_rest, self._ke, self._kappa_el)
        self.mu, self.lam, self._ke, self._kappa_el = self.mu * r, self.lam * r, self._ke * r[:, None, None], self._kappa_el * r
        self.kappa_node = self._scaled_kappa_node(np.ones_like(r))
        self._k_rest = self._assemble_stiffness(None)
        try:
            x = self._static_solve(forces, max_iter, tol)
        finally:
            self.mu, self.lam, self.kappa_node, self._k_rest, self._ke, self._kappa_el = saved
        self._instant_stress(self.positions, self._sig_prev)
        self._h[:] = 0.0
        self._pending_dt = 0.0
        return x

    def _static_solve(self, forces, max_iter, tol) -> np.ndarray:
        if not self.fixed.any():
            raise ConfigError("static_solve needs Dirichlet nodes (the free body has rigid modes); "
                              "call set_fixed(nodes) first")
        if forces is None:
            forces = self.external_forces
        forces = np.asarray(forces, dtype=np.float64)
        if forces.shape != self.positions.shape or not np.all(np.isfinite(forces)):
            raise ConfigError(f"forces must be a finite array of shape {self.positions.shape}, got {forces.shape}")
        validate.integer(max_iter, "max_iter", lo=1, fix="give a positive integer")
        validate.real(tol, "fem.static_solve: tol", lo=0.0, hi=1.0, lo_open=True, hi_open=True,
                      fix="it is update / body size, e.g. 1e-9")
        load = forces + self.masses[:, None] * self.gravity[None, :]
        free = ~self.fixed
        free3 = np.repeat(free, 3)
        x = self.positions.copy()
        x[self.fixed] = self.fixed_targets[self.fixed]
        size = float(np.ptp(self.rest_positions, axis=0).max())
        lu = None
        iters = max_iter if self.corotational else 1
        for it in range(iters):
            if self.corotational:
                self._update_rotations(x, tol=1e-12, max_iter=100)
                k = self._assemble_stiffness(self._rots)
                lu = spla.splu(k[free3][:, free3].tocsc())
            elif lu is None:
                lu = spla.splu(self._k_rest[free3][:, free3].tocsc())
            r = (load - self._stiffness_product(x, True)).ravel()
            dx = lu.solve(r[free3])
            if not np.all(np.isfinite(dx)):
                raise ConfigError("static_solve: singular stiffness (check that the fixed nodes hold the body)")
            x[free] += dx.reshape(-1, 3)
            self.static_iterations = it + 1
            if np.max(np.abs(dx)) < tol * size:
                break
        else:
            if self.corotational:
                raise StaticSolveError(
                    f"fem.static_solve (corotational) did not converge in max_iter={max_iter} iterations: the last "
                    f"update was {np.max(np.abs(dx)):.3g} m, above tol x body size = {tol:g} x {size:.3g} m. Raise "
                    "max_iter or tol, or apply the load/displacement in smaller steps (the rotations follow the "
                    "deformation by fixed-point iteration)")
        self.positions = x
        self.velocities = np.zeros_like(x)
        return x.copy()

    def _reset_state(self) -> None:
        self._rots[:] = np.eye(3)
        self._v_prev = None
        self._h[:] = 0.0
        self._sig_prev[:] = 0.0
        self._pending_dt = 0.0

    def describe(self) -> dict:
        out = super().describe()
        out.update(corotational=self.corotational, formulation=self.formulation,
                   stiffness_damping=self.stiffness_damping, threads=self.threads,
                   preconditioner=self.preconditioner)
        return out

    # ------------------------------------------------------------------------------------------
    # Growth (Vandewalle et al. 2003, section 2.3): surgsim_envs.tissue.growth
    def grow(self, k: float = 20.0, alpha="auto", **kwargs):
        """Stress-induced tissue growth from the current Dirichlet nodes/targets (bone displacement);
        sets ``positions`` to the grown equilibrium, returns a ``GrowthResult``. See
        :func:`surgsim_envs.tissue.growth.grow` and docs/models/growth.md."""
        from surgsim_envs.tissue.growth import grow

        return grow(self, k, alpha, **kwargs)
