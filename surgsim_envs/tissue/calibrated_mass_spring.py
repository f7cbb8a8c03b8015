"""``mass_spring_calibrated``: the paper-002 mass-spring network with spring constants identified
from linear elasticity, so that its small-strain response matches FEM.

Same springs law, Maxwell branches, nodal damping and integrators as :class:`MassSpringModel`
(``auto``/``symplectic``/``implicit``), but

* the springs are the tet edges plus cross-face springs, with constants fitted per spring so
  that every node's share of the network carries the material's ``mu T`` (the fully symmetric
  part of isotropic elasticity) -- see :mod:`surgsim_envs.tissue.spring_calibration`;
* a volume term on the averaged nodal volumes carries the rest, ``lambda - mu`` (no locking as
  nu -> 0.5), numba kernels in :mod:`surgsim_envs.tissue.nodal_volume_kernels`.

The viscoelastic split is the base model's: ``K1 = (1 - g1) k``, ``kM = g1 k`` per spring with the
spring's ``relax_fraction``/``relax_time``/``nonlinear`` the E V-weighted mean of its two end
nodes' tets; the volume term is elastic (bulk does not relax).
Docs: docs/models/mass_spring_calibrated.md.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, Mapping

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.tissue import msd_kernels as kern
from surgsim_envs.tissue import nodal_volume_kernels as nvk
from surgsim_envs.tissue.base import AUTO_RECHECK_STEPS, DT_SAFETY
from surgsim_envs.tissue.mass_spring import (CG_MAX_ITER, NONLINEAR_NETWORK_FACTOR, MassSpringModel,
                                             _finite_non_negative)
from surgsim_envs.tissue.spring_calibration import calibrate, calibration_basis

#: factor on the Lanczos estimate of the largest eigenvalue in :meth:`CalibratedMassSpringModel.critical_dt`
#: (the Ritz value approaches lambda_max from below; DT_SAFETY applies on top of it)
LANCZOS_MARGIN = 1.05
#: the Lanczos estimate is used only down to bound / LANCZOS_FLOOR (the bound is 2-3x the exact value)
LANCZOS_FLOOR = 16.0
#: critical_dt() runs the Lanczos estimate (~4 ms for the 232-node spleen, 30-70 ms for the palpation slab) once
#: per this many steps (and after reset / a material change); in between it scales the bound by the last
#: Lanczos/bound ratio (the bound, Gershgorin + volume_lambda_bound, costs ~0.1 ms)
LANCZOS_REFRESH_STEPS = 2000
#: "auto" sub-cycles the explicit step (integrator "subcycled") up to this many symplectic steps per dt
#: before it takes the implicit one: one implicit step costs 6-13 symplectic ones here (CHANGELOG.md
#: "Calibrated mass-spring: linear calibration basis, sub-cycled integrator")
MAX_SUBCYCLES = 4
#: selective mass scaling (default ``mass_scaling``): a node whose geometric frequency w_a = sum_t |dV_t/dx_a|^2 / V_t
#: over its nodal volume exceeds this many times the median gets its mass raised to bring it back to that ratio.
#: Only sliver tets trigger it (lattices, graded slabs: max 1.3-1.9x the median); on the Grasp spleen 36 of 232
#: nodes, +0.74 % mass, exact critical dt 0.52 -> 0.86 ms (docs/models/mass_spring_calibrated.md)
MASS_SCALING_RATIO = 4.0


def sliver_mass_factors(volume, ratio: float) -> np.ndarray:
    """(N,) factors >= 1 on the lumped masses: node a's geometric frequency w_a = sum_{t ∋ a} |dV_t/dx_a|^2 / V_t
    / (sum_{t ∋ a} V_t / 4) (1/m^2; its explicit limit is ~ 1/sqrt(w_a) times the P-wave speed) above ``ratio``
    x the median is brought back to it by mass (factor w_a / (ratio median)). A node that touches only flat tets
    has a tiny mass but not a tiny stiffness and alone sets the explicit step; the mass added there changes
    nothing else (explicit-dynamics practice: selective mass scaling)."""
    X = np.ascontiguousarray(volume.nodes, dtype=np.float64)
    tets = np.ascontiguousarray(volume.tets, dtype=np.int64)
    g = np.zeros((len(tets), 4, 3))
    nvk.tangents(X, tets, g)
    vol = volume.tet_volumes()
    n = len(X)
    stiff = np.bincount(tets.ravel(), weights=(np.einsum("tak,tak->ta", g, g) / vol[:, None]).ravel(), minlength=n)
    node_vol = np.bincount(tets.ravel(), weights=np.repeat(vol / 4.0, 4), minlength=n)
    w = stiff / node_vol
    cap = ratio * float(np.median(w))
    return np.where(w > cap, w / cap, 1.0)


class CalibratedMassSpringModel(MassSpringModel):
    """Mass-spring-damper network whose spring constants and nodal volume term are identified from
    the material's (E, nu) per tet (see module docstring).

    Parameters: as :class:`MassSpringModel` except ``springs``, ``K1`` and ``volume_stiffness``
    (set by the calibration); ``K2``, ``b0``, ``b1`` overrides work as there. ``mass_scaling``: selective
    mass scaling of sliver nodes (:func:`sliver_mass_factors`, default ``MASS_SCALING_RATIO``; None: plain
    lumped masses).
    ``calibration`` (after construction) holds the fitted springs and the fit residual.
    """

    name: ClassVar[str] = "mass_spring_calibrated"
    compiled_step_module: ClassVar[str | None] = "surgsim_envs.tissue.calibrated_mass_spring_compiled"
    summary: ClassVar[str] = ("mass-spring network (the grasping simulation paper) with spring constants and a nodal volume term "
                              "identified from linear elasticity (matches FEM at small strain), auto/symplectic/implicit")
    capabilities: ClassVar[frozenset[str]] = frozenset({"forces", "unstructured_mesh", "implicit_contact", "viscoelastic",
                                                    "subsurface_stiffness"})
    #: "subcycled": the symplectic step split into n = ceil(dt / stable_dt()) equal steps under the same
    #: external forces (n re-evaluated with critical_dt(), as "auto" does); "auto" takes it instead of
    #: "implicit" while n <= MAX_SUBCYCLES and the contact stiffness alone is stable at dt
    integrators: ClassVar[tuple[str, ...]] = ("symplectic", "implicit", "subcycled")
    #: the calibrated volume term already keeps tets under a concentrated load from collapsing
    point_load_options: ClassVar[Mapping[str, Any]] = {}
    implicit_point_load_options: ClassVar[Mapping[str, Any]] = {}

    def __init__(self, volume, material="liver", *, integrator=None, K2=None, b0=None, b1=None,
                 mass_scaling: float | None = MASS_SCALING_RATIO, **base_kwargs):
        number = isinstance(mass_scaling, (int, float)) and not isinstance(mass_scaling, bool)
        if mass_scaling is not None and not (number and math.isfinite(mass_scaling) and mass_scaling >= 1):
            raise ConfigError(f"mass_spring_calibrated: mass_scaling={mass_scaling!r} must be a number >= 1 (times the "
                              "median geometric frequency a node may reach before mass is added) or None (off)")
        self.mass_scaling = mass_scaling
        for key in ("K1", "springs", "volume_stiffness"):
            if key in base_kwargs:
                raise ConfigError(f"mass_spring_calibrated: {key} is set by the calibration; use model 'mass_spring' "
                                  f"to choose {key} yourself")
        super().__init__(volume, material, integrator=integrator, K2=K2, b0=b0, b1=b1, **base_kwargs)
        n = self.n_nodes
        self._vbuf = np.zeros(n)
        self._fvol = np.zeros((n, 3))
        self._subcycles, self._sub_dt, self._sub_step = 0, math.nan, 0
        self._lanczos_step = 0

    # ---------------------------------------------------------------------------------------
    # Parameters (hooks called by MassSpringModel.__init__)
    def _lumped_masses(self) -> np.ndarray:
        """Row-sum lumped masses times :func:`sliver_mass_factors` (selective mass scaling, ``mass_scaling``)."""
        m = super()._lumped_masses()
        if self.mass_scaling is None:
            return m
        factors = getattr(self, "_mass_factors", None)
        if factors is None:
            factors = self._mass_factors = sliver_mass_factors(self.volume, self.mass_scaling)
        return m * factors

    def _setup_volume_term(self, volume_stiffness) -> None:
        super()._setup_volume_term(None)           # no per-tet term
        previous = getattr(self, "calibration", None)
        young, poisson = np.array(self.fields["young"], dtype=np.float64), np.array(self.fields["poisson"])
        if np.all(poisson >= 0.25):
            # linear in the moduli: one fit per mesh, then sparse products (scale_material costs ~ms)
            if getattr(self, "_basis", None) is None:
                self._basis = calibration_basis(self.volume)
            self.calibration = self._basis.calibration(young, poisson)
        else:
            # some nu < 1/4: a non-negative fit of the field itself, from the old springs rescaled per spring
            initial = None if previous is None else previous.stiffness * self._spring_young_ratio(previous.pairs)
            self.calibration = calibrate(self.volume, young, poisson, initial=initial)
        self._calibrated_young = young
        if getattr(self, "node_rest_volume", None) is None:
            tets = np.ascontiguousarray(self.volume.tets, dtype=np.int64)
            v0 = np.zeros(self.n_nodes)
            nvk.node_volumes(np.ascontiguousarray(self.rest_positions), tets, v0)
            if np.any(v0 <= 0):
                raise ConfigError(f"mass_spring_calibrated: volume '{self.volume.name}' has nodes with non-positive "
                                  "volume; the volume term needs positively oriented tets")
            self.node_rest_volume = v0
            self._all_tets = tets
        self.node_bulk = np.ascontiguousarray(self.calibration.node_bulk)
        # the volume term only where nu needs it: no tets to visit when every k_v is 0 (nu <= 1/4 and
        # springs that fit); the kernels then cost nothing
        ntets = self._all_tets if np.any(self.node_bulk > 0) else np.zeros((0, 4), dtype=np.int64)
        if len(ntets) != len(getattr(self, "_ntets", ())):
            self._ntets = ntets
            self._cg = None            # implicit buffers (sized by springs and tets) follow on first use
            self._gpattern = None      # sparsity of the nodal gradients (volume_lambda_bound), on first use
        self._lanczos_ratio = None     # critical_dt() runs Lanczos again for the new constants
        self.volume_stiffness = "calibrated"

    @property
    def volume_tets(self) -> np.ndarray:
        """(T, 4) node indices of the tets the nodal volume term visits (none where every node's
        bulk term is zero)."""
        return self._ntets

    def _build_springs(self, overrides) -> None:
        if overrides.get("K1") is not None:
            raise ConfigError("mass_spring_calibrated: K1 is set by the calibration (material.extra has 'K1'); "
                              "use model 'mass_spring' for a fixed K1")
        cal = self.calibration
        # springs the fit left at exactly 0 (20-35 % of the layout: body diagonals and long cross-face
        # springs inside a lattice) carry nothing, linear, cubic or Maxwell: leave them out of the kernels
        live = cal.stiffness > 0.0
        pairs = cal.pairs[live]
        n = self.n_nodes
        self.springs = pairs
        self.si = np.ascontiguousarray(pairs[:, 0])
        self.sj = np.ascontiguousarray(pairs[:, 1])
        X = self.rest_positions
        L0 = np.linalg.norm(X[self.sj] - X[self.si], axis=1)
        self.rest_lengths = L0
        tets = self.volume.tets.astype(np.int64).reshape(-1)
        f = self.fields
        w_tet = np.repeat(f["young"] * self.volume.tet_volumes() / 4.0, 4)
        wnode = np.bincount(tets, weights=w_tet, minlength=n)

        def spring_mean(field: str) -> np.ndarray:
            node = np.bincount(tets, weights=w_tet * np.repeat(f[field], 4), minlength=n) / wnode
            return 0.5 * (node[self.si] + node[self.sj])

        g1, tau, nonlin = spring_mean("relax_fraction"), spring_mean("relax_time"), spring_mean("nonlinear")
        k = cal.stiffness[live]
        self.edge_stiffness = k
        K1 = (1.0 - g1) * k
        K2 = (np.full(len(k), overrides["K2"]) if overrides.get("K2") is not None
              else NONLINEAR_NETWORK_FACTOR * nonlin * K1 / (3.0 * L0 ** 2))
        kM = g1 * k
        if overrides.get("b1") is not None:
            b1 = np.full(len(k), overrides["b1"])
        else:
            b1 = kM * tau
        if overrides.get("b0") is not None:
            b0 = np.full(n, overrides["b0"])
        else:
            b0 = np.zeros(n)
            vol = self.volume.tet_volumes()
            np.add.at(b0, tets, np.repeat(f["damping"] * f["density"] * vol / 4.0, 4))
        self.K1, self.K2, self.kM, self.b1, self.b0 = K1, K2, kM, b1, b0
        with np.errstate(divide="ignore", invalid="ignore"):
            self.tau = np.where(kM > 0, b1 / np.where(kM > 0, kM, 1.0), np.inf)
        if hasattr(self, "_s") and len(self._s) != len(k):   # a refit changed which springs live:
            self._s = np.zeros(len(k))                        # Maxwell state restarts (scale_material
            self._dl = np.zeros(len(k))                       # is called between episodes)
            self._cg = None

    # ---------------------------------------------------------------------------------------
    # Integrator choice: explicit sub-cycles before implicit
    def _pick(self, dt: float, crit: float, contact_rate: float) -> str:
        choice = super()._pick(dt, crit, contact_rate)
        if choice != self.auto_pair[1] or not (crit > 0) or not math.isfinite(crit):
            return choice
        n = math.ceil(dt / (DT_SAFETY * crit) - 1e-12)
        # the contact force is held over the sub-steps: its own explicit limit applies to dt
        contact_ok = contact_rate <= 0 or dt <= DT_SAFETY * 2.0 / math.sqrt(contact_rate)
        if n <= MAX_SUBCYCLES and contact_ok:
            self._subcycles = n
            return "subcycled"
        return choice

    def subcycle_count(self, dt: float) -> int:
        """Symplectic steps per step of ``dt`` s under integrator "subcycled": ceil(dt / stable_dt()), with
        critical_dt() re-evaluated when dt changes, every AUTO_RECHECK_STEPS steps and after reset."""
        if self.integrator == "auto" and self._subcycles:
            return self._subcycles
        if dt != self._sub_dt or self.steps - self._sub_step >= AUTO_RECHECK_STEPS or not self._subcycles:
            self._subcycles = max(1, math.ceil(dt / self.stable_dt() - 1e-12))
            self._sub_dt, self._sub_step = dt, self.steps
        return self._subcycles

    def _reset_state(self) -> None:
        super()._reset_state()
        self._subcycles, self._sub_dt, self._sub_step = 0, math.nan, 0
        self._lanczos_ratio = None

    # ---------------------------------------------------------------------------------------
    # Stepping
    def _advance(self, dt: float, forces: np.ndarray, stiffness: np.ndarray | None) -> None:
        kMg, decay = self._branch_coeffs(self._pending_dt)
        fext = (forces if forces.dtype == np.float64 and forces.flags.c_contiguous
                else np.ascontiguousarray(forces, dtype=np.float64))
        if stiffness is None:
            kc = self._zero_kc
        else:
            kc = np.ascontiguousarray(stiffness, dtype=np.float64)
            if kc.shape != (self.n_nodes,) or not _finite_non_negative(kc):
                raise ConfigError(f"stiffness must be a finite, non-negative ({self.n_nodes},) array in N/m, "
                                  f"got shape {np.shape(stiffness)}")
        active = self._active or self.active_integrator
        if active != "implicit":
            n = self.subcycle_count(dt) if active == "subcycled" else 1
            h = dt / n
            kMg_h, decay_h = self._branch_coeffs(h) if n > 1 else (kMg, decay)
            nvk.symplectic_substeps(n, h, self.positions, self.velocities, self.inv_mass, self.b0, fext, self.gravity,
                                    self.fixed, self.si, self.sj, self.rest_lengths, self.K1, self.K2, kMg, decay,
                                    kMg_h, decay_h, self._s, self._dl, self._f, self._fvol, self.spring_work(),
                                    self._vtets, self.volume_rest, self.volume_kv, self._ntets,
                                    self.node_rest_volume, self.node_bulk, self._vbuf)
            self._pending_dt = h
            return
        kMg_next, _ = self._branch_coeffs(dt)
        if self._cg is None:
            self._allocate_implicit_buffers()
        r, z, p, ap, pre = self._cg
        self.last_cg_iterations = nvk.implicit_step(
            self.positions, self.velocities, self.masses, self.b0, fext, self.gravity, self.fixed, kc, dt,
            self.si, self.sj, self.rest_lengths, self.K1, self.K2, kMg, decay, kMg_next, self._s, self._dl,
            self._f, self._coef_a, self._coef_g, self._unit, self._diag, pre, r, z, p, ap,
            self.cg_tol, CG_MAX_ITER, self._ntets, self.node_rest_volume, self.node_bulk,
            self._ngrad, self._nc, self._vbuf, self._nsbuf)
        if stiffness is not None:   # backward Euler integrated f_ext - kc (x_{n+1} - x_n) = f_ext - dt kc v_{n+1}
            free = ~self.fixed
            self.integrated_external_forces[free] -= (dt * kc[free])[:, None] * self.velocities[free]
        self._pending_dt = dt

    def _allocate_implicit_buffers(self) -> None:
        super()._allocate_implicit_buffers()
        self._ngrad = np.zeros((len(self._ntets), 4, 3))
        self._nc = np.zeros(self.n_nodes)
        self._nsbuf = np.zeros(self.n_nodes)
        self.notify_changed()

    # ---------------------------------------------------------------------------------------
    # Forces, energies, stiffness
    def volume_forces(self, positions: np.ndarray | None = None) -> np.ndarray:
        """(N,3) nodal forces (N) of the nodal volume term at ``positions`` (default current)."""
        x = self.positions if positions is None else np.ascontiguousarray(positions, dtype=np.float64)
        out = np.zeros_like(x)
        nvk.add_forces(x, self._ntets, self.node_rest_volume, self.node_bulk, np.zeros(len(x)), out)
        return out

    def volume_energy(self, positions: np.ndarray | None = None) -> float:
        """Energy (J) of the nodal volume term, sum 0.5 k_v,i (V_i - V0_i)^2 / V0_i."""
        x = self.positions if positions is None else np.ascontiguousarray(positions, dtype=np.float64)
        return float(nvk.energy(x, self._ntets, self.node_rest_volume, self.node_bulk, np.zeros(len(x))))

    def internal_forces(self) -> np.ndarray:
        """(N,3) springs + Maxwell branches + nodal volume term + nodal damping (N)."""
        return self.spring_forces() - self.b0[:, None] * self.velocities + self.volume_forces()

    def critical_dt(self) -> float:
        """Largest stable dt (s) of the symplectic integrator: 2/sqrt(lambda) with nodal damping, lambda the
        largest eigenvalue of M^-1 K (springs with their instantaneous Maxwell stiffness, tension
        geometric term, nodal volume term) at the current state, from a matrix-free Lanczos estimate
        (scipy ``eigsh``, relative tolerance 1e-3) raised by ``LANCZOS_MARGIN``; never below the guaranteed
        bound (Gershgorin for the springs + :meth:`volume_lambda_bound`), which alone cut the stable dt to
        0.4-0.6 of the exact one. The Lanczos run is refreshed every LANCZOS_REFRESH_STEPS steps, after
        reset() and after a material change; in between the bound at the current state is scaled by the
        last Lanczos/bound ratio. Contact stiffness is not included (as in ``mass_spring``)."""
        kMg, decay = self._branch_coeffs(self._pending_dt)
        bound = float(kern.gershgorin_lambda_max(self.positions, self.inv_mass, self.si, self.sj, self.rest_lengths,
                                                 self.K1, self.K2, self.kM, self._s, self._dl, decay, kMg,
                                                 self._vtets, self.volume_rest, self.volume_kv))
        bound += self.volume_lambda_bound()
        if self._lanczos_ratio is None or self.steps - self._lanczos_step >= LANCZOS_REFRESH_STEPS:
            try:
                ratio = LANCZOS_MARGIN * self._lanczos_lambda() / bound if bound > 0 else 1.0
            except Exception:  # noqa: BLE001 - ARPACK may not converge; the guaranteed bound stands
                ratio = 1.0
            self._lanczos_ratio, self._lanczos_step = ratio, self.steps
        # the bound overestimates by 2-3x here; never trust an estimate LANCZOS_FLOOR times below it
        lam = bound * min(1.0, max(self._lanczos_ratio, 1.0 / LANCZOS_FLOOR))
        beta = float(np.max(self.b0 * self.inv_mass)) if self.n_nodes else 0.0
        if lam <= 0:
            return math.inf if beta == 0 else 2.0 / beta
        return (-beta + math.sqrt(beta * beta + 4.0 * lam)) / lam

    def _lanczos_lambda(self) -> float:
        """Largest eigenvalue (1/s^2) of M^-1/2 K M^-1/2 on the free nodes, matrix-free (numba products)."""
        import scipy.sparse.linalg as spla

        n, ne = self.n_nodes, len(self.si)
        ca, cg, unit = np.zeros(ne), np.zeros(ne), np.zeros((ne, 3))
        kern.spring_tangents(self.positions, self.si, self.sj, self.rest_lengths, self.K1, self.K2, self.kM,
                             self._s, True, ca, cg, unit)
        vgrad = np.zeros((len(self._ntets), 4, 3))
        nvk.tangents(self.positions, self._ntets, vgrad)
        c = self.node_bulk / self.node_rest_volume
        s = np.repeat(np.where(self.fixed, 0.0, np.sqrt(self.inv_mass)), 3)
        zero_m, sbuf, out = np.zeros(n), np.zeros(n), np.zeros((n, 3))
        no_t, no_g, no_c = np.zeros((0, 4), dtype=np.int64), np.zeros((0, 4, 3)), np.zeros(0)

        def matvec(y):
            x = np.ascontiguousarray((np.ravel(y) * s).reshape(n, 3))
            kern._system_matvec(x, zero_m, 1.0, self.si, self.sj, ca, cg, unit, self.fixed, out, no_t, no_g, no_c)
            nvk.matvec_add(x, 1.0, self._ntets, vgrad, c, sbuf, out)
            return out.ravel() * s

        op = spla.LinearOperator((3 * n, 3 * n), matvec=matvec, dtype=np.float64)
        v0 = np.cos(np.arange(3 * n) * 0.7071) * s
        return float(spla.eigsh(op, k=1, which="LA", tol=1e-3, v0=v0, return_eigenvectors=False)[0])

    def volume_lambda_bound(self, positions: np.ndarray | None = None) -> float:
        """Upper bound (1/s^2) of the largest eigenvalue of M^-1 K_v, K_v = sum_i c_i G_i G_i^T the nodal
        volume term's Gauss-Newton tangent (c_i = k_v,i / V0_i, G_i = dV_i/dx). By Cauchy-Schwarz,
        (G_i . x)^2 <= g_i sum_{a in S_i} m_a |x_a|^2 with g_i = sum_a |G_ia|^2 / m_a (S_i: node i's
        1-ring), so x^T K_v x <= max_a (sum_{i: a in S_i} c_i g_i) x^T M x. About 2x tighter than
        the absolute row sums (a Gershgorin-style bound), which cuts the stable dt of the
        5 mm palpation slab to 0.41 of its eigenvalue-exact value."""
        x = self.positions if positions is None else np.ascontiguousarray(positions, dtype=np.float64)
        if self._gpattern is None:
            self._gpattern = nvk.gradient_pattern(self._ntets, self.n_nodes)
        indptr, cols, slot = self._gpattern
        return float(nvk.lambda_bound(x, self._ntets, slot, indptr, cols, self.node_bulk / self.node_rest_volume,
                                      self.inv_mass, self.fixed, np.empty((len(cols), 3)), np.empty(self.n_nodes)))

    def _tangent(self, positions: np.ndarray, relaxed: bool, clamp: bool):
        """Springs (base class) plus the nodal volume term's Gauss-Newton tangent sum_i c_i G_i G_i^T."""
        import scipy.sparse as sp

        k = super()._tangent(positions, relaxed, clamp)
        tets = self._ntets
        nt, n = len(tets), self.n_nodes
        g = np.zeros((nt, 4, 3))
        nvk.tangents(np.ascontiguousarray(positions), tets, g)
        rows = np.repeat(tets, 12, axis=1).ravel()                       # node i of the tet ...
        cols = np.tile((3 * tets[:, :, None] + np.arange(3)).reshape(nt, 12), (1, 4)).ravel()   # ... dof of node a
        vals = np.tile(0.25 * g.reshape(nt, 12), (1, 4)).ravel()
        G = sp.csr_matrix((vals, (rows, cols)), shape=(n, 3 * n))
        c = self.node_bulk / self.node_rest_volume
        return (k + (G.T @ sp.diags(c) @ G)).tocsr()

    def static_solve(self, forces=None, **kwargs):
        """Not available yet: raises NotImplementedError (callers such as scripts/truthcube.py then relax
        dynamically)."""
        raise NotImplementedError("mass_spring_calibrated has no static_solve yet (its Newton residual would miss "
                                  "the nodal volume term); step it to rest, or use model 'fem' or 'mass_spring'")

    def describe(self):
        out = super().describe()
        out.update({"calibration_residual": self.calibration.residual,
                    "cross_springs": int(np.count_nonzero(self.calibration.stiffness[self.calibration.n_edges:] > 0)),
                    "zero_springs_left_out": int(np.count_nonzero(self.calibration.stiffness <= 0)),
                    "node_bulk_mean_Pa": float(self.node_bulk.mean()),
                    "mass_scaled_nodes": int(np.count_nonzero(getattr(self, "_mass_factors", np.ones(1)) > 1.0))})
        return out
