"""Nonlinear viscoelastic mass-spring-damper tissue (paper 002, eqs. 1-3).

Mass points sit at the volume's nodes (lumped masses ``m_i`` from the density), springs on the
tet edges, and every node has an absolute-velocity damper (eq. 2's ``-b_i v_i``). Each spring is
a nonlinear standard linear solid (see ``docs/models/mass_spring.md``):

    f_ij = K1_ij dl + K2_ij dl^3 + s_ij        (N, positive in tension), dl = |r_j - r_i| - L0_ij

* ``K1`` (N/m): long-term (relaxed) linear spring constant, ``(1 - g1) k_ij``;
* ``K2`` (N/m^3): cubic strain-stiffening term, ``(9/5) nonlinear * K1 / (3 L0^2)``, so that the
  relaxed tangent modulus of the network grows as ``E (1 + nonlinear * strain^2)`` as
  :class:`Material` describes (9/5 averages the spring directions; small-strain, affine limit);
* ``s`` (N): force of a Maxwell branch, spring ``kM = g1 k_ij = g1/(1-g1) K1`` in series with a
  dashpot ``b1`` (N s/m) = ``kM * tau``: ``ds/dt = kM d(dl)/dt - s kM / b1``. A held deformation
  relaxes from ``k`` to ``(1 - g1) k`` with time constant ``tau`` (paper Fig. 4);
* ``b0`` (N s/m): nodal damping, ``damping * m_i`` by default.

The instantaneous small-strain constant comes from Young's modulus of the tets around the edge:
``k_ij = c * sum_{t ∋ ij} E_t V_t / L0_ij^2`` with ``c = 1`` (an isotropic spread of edge directions
then gives exactly Young's modulus E with Poisson ratio 1/4; on the Kuhn box lattice it gives
1.034 E with nu ~ 0.03 — a spring network cannot represent an arbitrary Poisson ratio).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.tissue import msd_kernels as kern
from surgsim_envs.tissue.base import TissueModel

#: c in k_ij = c * sum_t E_t V_t / L0^2 (see module docstring and docs/models/mass_spring.md)
EDGE_STIFFNESS_FACTOR = 1.0
#: alpha in K2 = alpha * nonlinear * K1 / (3 L0^2). A spring at angle theta to a uniaxial strain eps
#: sees eps cos^2(theta); averaging the quartic energy over isotropic directions (<cos^4>/<cos^8> = 9/5)
#: makes the tissue-level tangent stiffness grow as k0 (1 + nonlinear * eps^2), as Material describes.
NONLINEAR_NETWORK_FACTOR = 9.0 / 5.0
#: relative residual at which the implicit step's conjugate gradients stop
CG_TOLERANCE = 1e-6
#: iteration cap of the implicit step's conjugate gradients
CG_MAX_ITER = 500


def _check_scalar(name: str, value: Any, *, positive: bool) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"mass_spring: {name}={value!r} must be a number (SI units)") from None
    if not math.isfinite(x):
        raise ConfigError(f"mass_spring: {name}={value!r} must be finite")
    if positive and x <= 0:
        raise ConfigError(f"mass_spring: {name}={value!r} must be > 0; it is a spring constant in N/m "
                          "(leave it None to derive it from the material's Young's modulus)")
    if x < 0:
        raise ConfigError(f"mass_spring: {name}={value!r} must be >= 0 (negative stiffness or damping "
                          "injects energy); leave it None to derive it from the material")
    return x


class MassSpringModel(TissueModel):
    """Nonlinear viscoelastic mass-spring-damper model on the tet edges (paper 002).

    Parameters
    ----------
    volume, material: see :class:`TissueModel`. Per-tet fields (``self.fields``) set the springs,
        so region materials (inclusions) make the springs around them stiffer.
    integrator: "symplectic" (semi-implicit Euler, explicit: dt < :meth:`critical_dt`) or
        "implicit" (backward Euler, one Newton step, conjugate gradients; stable at 1 ms).
    springs: "edges" (one spring per unique tet edge; the only layout so far).
    K1: long-term linear spring constant (N/m) for every spring, overriding the E-mapping.
    K2: cubic spring coefficient (N/m^3) for every spring, overriding ``nonlinear``.
    b0: nodal damping (N s/m) for every node, overriding ``damping * m_i``.
    b1: Maxwell dashpot (N s/m) for every spring, overriding ``kM * relax_time``; needs
        ``relax_fraction > 0`` (the branch spring ``kM = g1/(1-g1) K1``).
    The overrides may also come from ``material.extra`` ({"K1": ..., ...}); keywords win.
    **base_kwargs: region_materials, fixed, gravity, guard (see :class:`TissueModel`).
    """

    name: ClassVar[str] = "mass_spring"
    summary: ClassVar[str] = ("nonlinear viscoelastic mass-spring-damper on tet edges (paper 002): "
                              "cubic springs + Maxwell branches, symplectic or implicit")
    integrators: ClassVar[tuple[str, ...]] = ("symplectic", "implicit")

    def __init__(self, volume, material="liver", *, integrator=None, springs="edges",
                 K1=None, K2=None, b0=None, b1=None, **base_kwargs):
        if springs != "edges":
            raise ConfigError(f"mass_spring: springs={springs!r} is not supported; use springs='edges' "
                              "(one spring per tet edge)")
        super().__init__(volume, material, integrator=integrator, **base_kwargs)
        extra = dict(self.material.extra or {})
        overrides = {}
        for key, value in (("K1", K1), ("K2", K2), ("b0", b0), ("b1", b1)):
            value = extra.get(key) if value is None else value
            overrides[key] = None if value is None else _check_scalar(key, value, positive=(key == "K1"))
        self._build_springs(overrides)
        n, ne = self.n_nodes, len(self.springs)
        self.inv_mass = 1.0 / self.masses
        # Maxwell branch state: branch force s (N) and extension dl (m) at the last commit
        self._s = np.zeros(ne)
        self._dl = np.zeros(ne)
        self._pending_dt = 0.0
        self._coeff_cache: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        # work buffers (no allocation in the hot path)
        self._f = np.zeros((n, 3))
        self._zero_kc = np.zeros(n)
        if self.integrator == "implicit":
            self._coef_a = np.zeros(ne)
            self._coef_g = np.zeros(ne)
            self._unit = np.zeros((ne, 3))
            self._diag = np.zeros(n)
            self._cg = [np.zeros((n, 3)) for _ in range(5)]
        self.last_cg_iterations = 0

    # ---------------------------------------------------------------------------------------
    # Parameters
    def _build_springs(self, overrides: dict[str, float | None]) -> None:
        vol = self.volume
        n = vol.n_nodes
        edges = vol.edges().astype(np.int64)
        self.springs = edges
        self.si = np.ascontiguousarray(edges[:, 0])
        self.sj = np.ascontiguousarray(edges[:, 1])
        X = self.rest_positions
        L0 = np.linalg.norm(X[self.sj] - X[self.si], axis=1)
        if np.any(L0 <= 0):
            raise ConfigError(f"mass_spring: volume '{vol.name}' has coincident nodes (zero-length edge); merge them")
        self.rest_lengths = L0

        # tets around each edge: k_e = c * sum_t E_t V_t / L0^2; other fields E V-weighted means
        tets = vol.tets.astype(np.int64)
        pairs = np.sort(np.stack([tets[:, [0, 0, 0, 1, 1, 2]].ravel(), tets[:, [1, 2, 3, 2, 3, 3]].ravel()], axis=1), axis=1)
        edge_of = np.searchsorted(edges[:, 0] * n + edges[:, 1], pairs[:, 0] * n + pairs[:, 1])
        f = self.fields
        tet_vol = vol.tet_volumes()
        w_tet = f["young"] * tet_vol
        w = np.repeat(w_tet, 6)
        ne = len(edges)
        wsum = np.bincount(edge_of, weights=w, minlength=ne)

        def mean(field: str) -> np.ndarray:
            return np.bincount(edge_of, weights=w * np.repeat(f[field], 6), minlength=ne) / wsum

        k = EDGE_STIFFNESS_FACTOR * wsum / L0 ** 2
        g1, tau, nonlin = mean("relax_fraction"), mean("relax_time"), mean("nonlinear")
        self.edge_stiffness = k  # instantaneous small-strain constant (N/m)

        K1 = np.full(ne, overrides["K1"]) if overrides["K1"] is not None else (1.0 - g1) * k
        K2 = (np.full(ne, overrides["K2"]) if overrides["K2"] is not None
              else NONLINEAR_NETWORK_FACTOR * nonlin * K1 / (3.0 * L0 ** 2))
        kM = g1 / (1.0 - g1) * K1
        if overrides["b1"] is not None:
            if overrides["b1"] > 0 and np.any(kM <= 0):
                raise ConfigError("mass_spring: b1 (Maxwell dashpot) needs a Maxwell spring: set the material's "
                                  "relax_fraction > 0 (e.g. 0.5), or leave b1=None")
            b1 = np.full(ne, overrides["b1"])
        else:
            b1 = kM * tau
        if overrides["b0"] is not None:
            b0 = np.full(n, overrides["b0"])
        else:
            b0 = np.zeros(n)
            np.add.at(b0, tets.reshape(-1), np.repeat(f["damping"] * f["density"] * tet_vol / 4.0, 4))
        self.K1, self.K2, self.kM, self.b1, self.b0 = K1, K2, kM, b1, b0
        with np.errstate(divide="ignore", invalid="ignore"):
            self.tau = np.where(kM > 0, b1 / np.where(kM > 0, kM, 1.0), np.inf)

    def _branch_coeffs(self, h: float) -> tuple[np.ndarray, np.ndarray]:
        """(kMg, decay) of the Maxwell branches over an interval of ``h`` s (cached per h)."""
        hit = self._coeff_cache.get(h)
        if hit is not None:
            return hit
        if h <= 0:
            out = (self.kM.copy(), np.ones_like(self.kM))
        else:
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                x = h / self.tau  # 0 where tau is inf
                decay = np.exp(-x)
                ratio = np.where(x > 1e-12, -np.expm1(-x) / np.where(x > 1e-12, x, 1.0), 1.0 - 0.5 * x)
            out = (np.where(self.kM > 0, self.kM * ratio, 0.0), np.where(self.kM > 0, decay, 1.0))
        if len(self._coeff_cache) > 8:
            self._coeff_cache.clear()
        self._coeff_cache[h] = out
        return out

    @property
    def n_springs(self) -> int:
        return len(self.springs)

    # ---------------------------------------------------------------------------------------
    # Stepping
    def _advance(self, dt: float, forces: np.ndarray, stiffness: np.ndarray | None) -> None:
        kMg, decay = self._branch_coeffs(self._pending_dt)
        fext = forces if (forces.dtype == np.float64 and forces.flags.c_contiguous) else np.ascontiguousarray(forces, dtype=np.float64)
        if stiffness is None:
            kc = self._zero_kc
        else:  # contact stiffness: used by the implicit solve, validated for both
            kc = np.ascontiguousarray(stiffness, dtype=np.float64)
            if kc.shape != (self.n_nodes,) or not np.all(np.isfinite(kc)) or np.any(kc < 0):
                raise ConfigError(f"stiffness must be a finite, non-negative ({self.n_nodes},) array in N/m, "
                                  f"got shape {np.shape(stiffness)}")
        if self.integrator == "symplectic":
            kern.symplectic_step(self.positions, self.velocities, self.inv_mass, self.b0, fext, self.gravity,
                                 self.fixed, dt, self.si, self.sj, self.rest_lengths, self.K1, self.K2,
                                 kMg, decay, self._s, self._dl, self._f)
        else:
            kMg_next, _ = self._branch_coeffs(dt)
            r, z, p, ap, pre = self._cg
            self.last_cg_iterations = kern.implicit_step(
                self.positions, self.velocities, self.masses, self.b0, fext, self.gravity, self.fixed, kc, dt,
                self.si, self.sj, self.rest_lengths, self.K1, self.K2, kMg, decay, kMg_next, self._s, self._dl,
                self._f, self._coef_a, self._coef_g, self._unit, self._diag, pre, r, z, p, ap,
                CG_TOLERANCE, CG_MAX_ITER)
        self._pending_dt = dt

    def _reset_state(self) -> None:
        self._s[:] = 0.0
        self._dl[:] = 0.0
        self._pending_dt = 0.0

    # ---------------------------------------------------------------------------------------
    # Forces, energies, stiffness
    def branch_forces(self) -> np.ndarray:
        """(E,) Maxwell-branch force (N, tension positive) of each spring at the current state."""
        kMg, decay = self._branch_coeffs(self._pending_dt)
        out = np.empty(self.n_springs)
        kern.branch_forces(self.positions, self.si, self.sj, self.rest_lengths, kMg, decay, self._s, self._dl, out)
        return out

    def spring_forces(self) -> np.ndarray:
        """(N,3) nodal forces (N) of the springs and their Maxwell branches (no damping)."""
        kMg, decay = self._branch_coeffs(self._pending_dt)
        out = np.empty_like(self.positions)
        kern.spring_forces(self.positions, self.si, self.sj, self.rest_lengths, self.K1, self.K2, kMg, decay,
                           self._s, self._dl, False, out)
        return out

    def internal_forces(self) -> np.ndarray:
        """(N,3) springs + Maxwell branches + nodal damping ``-b0 v`` (N) at the current state."""
        return self.spring_forces() - self.b0[:, None] * self.velocities

    def elastic_energy(self) -> float:
        """Energy (J) in the springs (0.5 K1 dl^2 + 0.25 K2 dl^4) and Maxwell springs (s^2 / 2 kM)."""
        kMg, decay = self._branch_coeffs(self._pending_dt)
        return float(kern.elastic_energy(self.positions, self.si, self.sj, self.rest_lengths, self.K1, self.K2,
                                         self.kM, kMg, decay, self._s, self._dl))

    def critical_dt(self) -> float:
        """Largest stable dt (s) of the symplectic integrator, from a Gershgorin bound.

        lambda_max(M^-1 K) <= max row sum, with K the tangent stiffness at the current state
        (nonlinear term, tension geometric term and the instantaneous Maxwell stiffness kM);
        symplectic Euler with nodal damping beta = b0/m is stable for dt^2 lambda + 2 beta dt < 4.
        The bound is conservative: on the 5 mm box lattice the eigenvalue-exact limit is ~10 % larger.
        Contact stiffness passed to :meth:`step` is not included.
        """
        kMg, decay = self._branch_coeffs(self._pending_dt)
        lam = float(kern.gershgorin_lambda_max(self.positions, self.inv_mass, self.si, self.sj, self.rest_lengths,
                                               self.K1, self.K2, self.kM, self._s, self._dl, decay, kMg))
        beta = float(np.max(self.b0 * self.inv_mass)) if self.n_nodes else 0.0
        if lam <= 0:
            return math.inf if beta == 0 else 2.0 / beta
        return (-beta + math.sqrt(beta * beta + 4.0 * lam)) / lam

    def stiffness_matrix(self, relaxed: bool = False, clamp: bool = False):
        """Tangent stiffness ``-df/dx`` (scipy.sparse CSR, 3N x 3N, N/m, dof = 3 * node + axis).

        relaxed: long-term stiffness (Maxwell branches relaxed away); else the instantaneous one.
        clamp: drop compressive geometric stiffness so the matrix is positive semi-definite.
        """
        import scipy.sparse as sp

        ne = self.n_springs
        a, g, u = np.empty(ne), np.empty(ne), np.empty((ne, 3))
        if relaxed:
            kern.spring_tangents(self.positions, self.si, self.sj, self.rest_lengths, self.K1, self.K2,
                                 np.zeros(ne), np.zeros(ne), clamp, a, g, u)
        else:
            kern.spring_tangents(self.positions, self.si, self.sj, self.rest_lengths, self.K1, self.K2,
                                 self.kM, self.branch_forces(), clamp, a, g, u)
        blocks = a[:, None, None] * u[:, :, None] * u[:, None, :] + g[:, None, None] * np.eye(3)[None]
        ii = 3 * self.si[:, None] + np.arange(3)[None]
        jj = 3 * self.sj[:, None] + np.arange(3)[None]
        rows, cols, vals = [], [], []
        for (r, c, sign) in ((ii, ii, 1.0), (jj, jj, 1.0), (ii, jj, -1.0), (jj, ii, -1.0)):
            rows.append(np.repeat(r, 3, axis=1).ravel())
            cols.append(np.tile(c, (1, 3)).ravel())
            vals.append(sign * blocks.ravel())
        n3 = 3 * self.n_nodes
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n3, n3))

    # ---------------------------------------------------------------------------------------
    # Quasi-static equilibrium
    def static_solve(self, forces: np.ndarray | None = None, *, tol: float = 1e-8, max_iter: int = 50) -> np.ndarray:
        """Relaxed (long-term) equilibrium under ``forces`` (N,3) N plus gravity, fixed nodes held.

        Newton iterations with the clamped tangent and a backtracking line search. The Maxwell
        branches are taken as fully relaxed (zero force); the state is left at the solution with
        zero velocity. Returns a copy of the equilibrium positions (m).
        """
        import scipy.sparse.linalg as spla

        if not self.fixed.any():
            raise ConfigError("mass_spring.static_solve needs fixed nodes (set fixed=... or call set_fixed) "
                              "to remove rigid-body motion")
        n = self.n_nodes
        F = np.zeros((n, 3)) if forces is None else np.asarray(forces, dtype=np.float64)
        if F.shape != (n, 3) or not np.all(np.isfinite(F)):
            raise ConfigError(f"forces must be a finite ({n}, 3) array in N, got shape {F.shape}")
        F = F + self.masses[:, None] * self.gravity[None]
        free = np.repeat(~self.fixed, 3)
        ne = self.n_springs
        zeros_e = np.zeros(ne)
        buf = np.empty((n, 3))

        def residual(x: np.ndarray) -> np.ndarray:
            kern.spring_forces(x, self.si, self.sj, self.rest_lengths, self.K1, self.K2, zeros_e, zeros_e,
                               zeros_e.copy(), zeros_e.copy(), False, buf)
            return (buf + F).ravel()[free]

        x = np.ascontiguousarray(self.positions.copy())
        x[self.fixed] = self.fixed_targets[self.fixed]
        R = residual(x)
        scale = max(float(np.linalg.norm(F.ravel()[free])), float(np.linalg.norm(buf)), 1e-12)
        for _ in range(max_iter):
            if np.linalg.norm(R) <= tol * scale:
                break
            self.positions = x
            K = self.stiffness_matrix(relaxed=True, clamp=True)[free][:, free]
            dx = spla.spsolve(K.tocsc(), R)
            if not np.all(np.isfinite(dx)):
                raise ConfigError("mass_spring.static_solve: singular stiffness (is every part of the body "
                                  "connected to a fixed node?)")
            step = 1.0
            r0 = np.linalg.norm(R)
            for _ in range(12):
                trial = x.copy()
                trial.reshape(-1)[free] += step * dx
                Rt = residual(trial)
                if np.linalg.norm(Rt) < r0:
                    break
                step *= 0.5
            x, R = trial, Rt
        self.positions = np.ascontiguousarray(x)
        self.velocities = np.zeros_like(self.positions)
        d = self.positions[self.sj] - self.positions[self.si]
        self._dl[:] = np.linalg.norm(d, axis=1) - self.rest_lengths
        self._s[:] = 0.0
        self._pending_dt = 0.0
        return self.positions.copy()

    def describe(self) -> dict[str, Any]:
        out = super().describe()
        out.update({"springs": self.n_springs, "K1_mean_N_per_m": float(self.K1.mean()),
                    "K2_mean_N_per_m3": float(self.K2.mean()), "b0_mean_Ns_per_m": float(self.b0.mean()),
                    "b1_mean_Ns_per_m": float(self.b1.mean())})
        return out
