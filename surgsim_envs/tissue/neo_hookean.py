"""``neo_hookean``: quasi-static hyperelastic tet FEM for large strain (stable Neo-Hookean).

Strain energy per unit reference volume (Smith, de Goes, Kim 2018, "Stable Neo-Hookean flesh
simulation", ACM TOG 37(2), the rest-stable form with alpha = 1 + mu/lambda):

    Psi(F) = mu/2 (I_C - 3) - mu (J - 1) + k/2 (J - 1)^2,   I_C = tr(F^T F), J = det F

Expanding about F = I gives mu |eps|^2 + (k - mu)/2 tr(eps)^2, so k = lambda + mu reproduces the
Lame constants (mu, lambda) of the material at small strain; it is defined for inverted tets
(no log J). The last (volumetric) term is evaluated on averaged nodal volumes, J_i = V_i / V0_i
(Bonet & Burton 1998; as ``fem``'s ANP), so linear tets do not lock at nu -> 0.5:
E_vol = sum_i k_i/2 (V_i - V0_i)^2 / V0_i (kernels of
:mod:`surgsim_envs.tissue.nodal_volume_kernels`). The first two terms are per tet.

Solved quasi-statically (no inertia): :meth:`static_solve` applies the fixed-node travel and the
loads in increments and solves each by projected Newton (per-tet 9x9 Hessians clamped to positive
semi-definite, Gauss-Newton nodal-volume tangent, sparse direct solve, Armijo line search on the
energy). :meth:`step` does the same from the current state with the given external forces
(velocities are finite differences). Units: m, Pa, N, J.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError, SurgSimError
from surgsim_envs.tissue import fem_assembly as asm
from surgsim_envs.tissue import nodal_volume_kernels as nvk
from surgsim_envs.tissue.base import TissueModel

_EPS = np.zeros((3, 3, 3))
_EPS[0, 1, 2] = _EPS[1, 2, 0] = _EPS[2, 0, 1] = 1.0
_EPS[0, 2, 1] = _EPS[2, 1, 0] = _EPS[1, 0, 2] = -1.0


class HyperelasticSolveError(SurgSimError, RuntimeError):
    """The Newton solve of :class:`NeoHookeanModel` found no equilibrium."""


class NeoHookeanModel(TissueModel):
    """Stable Neo-Hookean tets with averaged-nodal volumetric term, quasi-static (see module docstring).

    newton_tol: relative residual |f_free| / (load scale) at which Newton stops.
    max_iter: Newton iterations per load increment.
    """

    name: ClassVar[str] = "neo_hookean"
    summary: ClassVar[str] = ("stable Neo-Hookean tets (Smith 2018) with averaged nodal volume, quasi-static "
                              "projected-Newton solve: large-strain hyperelasticity")
    integrators: ClassVar[tuple[str, ...]] = ("quasi_static",)
    capabilities: ClassVar[frozenset[str]] = frozenset({"forces", "unstructured_mesh", "quasi_static", "static_solve",
                                                    "subsurface_stiffness"})
    #: material fields scale_material / set_field may change (the model re-derives its constants)
    material_fields: ClassVar[tuple[str, ...]] = ("young", "poisson")

    def __init__(self, volume, material="silicone", *, newton_tol: float = 1e-8, max_iter: int = 30,
                 c01_fraction: float = 0.0, **base_kwargs):
        super().__init__(volume, material, **base_kwargs)
        validate.real(c01_fraction, "c01_fraction", lo=0.0, hi=1.0,
                      fix="the share of the shear modulus carried by the Mooney-Rivlin I2 term; 0 = Neo-Hookean")
        self.c01_fraction = float(c01_fraction)
        validate.real(newton_tol, "newton_tol", lo=0.0, hi=1.0, lo_open=True, hi_open=True,
                      fix="a relative residual, e.g. 1e-8")
        validate.integer(max_iter, "max_iter", lo=1, fix="Newton iterations per load increment, e.g. 30")
        self.newton_tol, self.max_iter = float(newton_tol), int(max_iter)
        self.tets = np.ascontiguousarray(volume.tets, dtype=np.int64)
        self.grads, self.tet_volume, _ = asm.shape_gradients(self.rest_positions, self.tets)
        n = self.n_nodes
        self.node_rest_volume = np.zeros(n)
        nvk.node_volumes(np.ascontiguousarray(self.rest_positions), self.tets, self.node_rest_volume)
        self._derive_material()
        nt = len(self.tets)
        # dF/dx: F_ij = sum_a x_ai g_aj -> B (T, 9, 12), row 3i+j, column 3a+i
        B = np.zeros((nt, 9, 12))
        for a in range(4):
            for i in range(3):
                B[:, 3 * i:3 * i + 3, 3 * a + i] = self.grads[:, a, :]
        self._B = B
        dof = (3 * self.tets[:, :, None] + np.arange(3)).reshape(nt, 12)
        self._rows = np.repeat(dof, 12, axis=1).ravel()
        self._cols = np.tile(dof, (1, 12)).ravel()
        self._vbuf = np.zeros(n)
        self.integrated_external_forces = np.zeros((n, 3))
        self.last_newton_iterations = 0

    def _derive_material(self) -> None:
        """Per-tet Mooney-Rivlin constants and nodal bulk moduli from the young/poisson fields."""
        E, nu = self.fields["young"], self.fields["poisson"]
        if np.any(nu >= 0.5) or np.any(nu <= -1) or np.any(E <= 0):
            raise ConfigError("neo_hookean needs E > 0 and -1 < nu < 0.5 in every tet (use nu <= 0.499)")
        self.mu, lam, _ = asm.lame_parameters(E, nu)
        # mu = 2 (C10 + C01): C10 = (1 - f) mu / 2, C01 = f mu / 2
        self._c10 = (1.0 - self.c01_fraction) * self.mu / 2.0
        self._c01 = self.c01_fraction * self.mu / 2.0
        self._beta = 2.0 * self._c10 + 4.0 * self._c01     # rest stability: P(I) = 0
        # small-strain Lame lambda = k - (1 - c01_fraction) mu (checked numerically in the tests)
        self.node_bulk = asm.nodal_average(self.tets, self.tet_volume, lam + (1.0 - self.c01_fraction) * self.mu,
                                           self.n_nodes)

    def _on_material_changed(self, name: str) -> None:
        self._derive_material()

    # ------------------------------------------------------------------------------------------
    def _deformation(self, x):
        return np.einsum("tai,taj->tij", x[self.tets], self.grads)

    def _energy(self, x, F_ext) -> float:
        F = self._deformation(x)
        J = np.linalg.det(F)
        C = np.einsum("tki,tkj->tij", F, F)
        i1 = np.einsum("tii->t", C)
        i2 = 0.5 * (i1 ** 2 - np.einsum("tij,tij->t", C, C))
        psi = self._c10 * (i1 - 3.0) + self._c01 * (i2 - 3.0) - self._beta * (J - 1.0)
        e = float(np.sum(self.tet_volume * psi))
        e += float(nvk.energy(np.ascontiguousarray(x), self.tets, self.node_rest_volume, self.node_bulk, self._vbuf))
        return e - float(np.sum(F_ext[~self.fixed] * x[~self.fixed]))

    def _forces(self, x) -> np.ndarray:
        """Internal elastic forces (N,3) N at x."""
        F = self._deformation(x)
        # cof F = J F^-T from cross products of F's columns: defined for degenerate (J = 0) tets too
        cof = np.stack([np.cross(F[:, :, 1], F[:, :, 2]), np.cross(F[:, :, 2], F[:, :, 0]),
                        np.cross(F[:, :, 0], F[:, :, 1])], axis=2)
        C = np.einsum("tki,tkj->tij", F, F)
        i1 = np.einsum("tii->t", C)
        FC = np.einsum("tik,tkj->tij", F, C)
        P = (2.0 * self._c10[:, None, None] * F + 2.0 * self._c01[:, None, None] * (i1[:, None, None] * F - FC)
             - self._beta[:, None, None] * cof)
        fa = -np.einsum("t,tij,taj->tai", self.tet_volume, P, self.grads)
        out = np.zeros_like(x)
        np.add.at(out, self.tets.reshape(-1), fa.reshape(-1, 3))
        nvk.add_forces(np.ascontiguousarray(x), self.tets, self.node_rest_volume, self.node_bulk, self._vbuf, out)
        return out

    def _hessian(self, x) -> sp.csr_matrix:
        F = self._deformation(x)
        dcof = np.einsum("ikn,jlq,tnq->tijkl", _EPS, _EPS, F).reshape(-1, 9, 9)
        C = np.einsum("tki,tkj->tij", F, F)
        i1 = np.einsum("tii->t", C)
        eye3 = np.eye(3)
        FF = np.einsum("tij,tkl->tijkl", F, F)
        # d(F F^T F)_ij / dF_kl = d_ik C_lj + F_il F_kj + (F F^T)_ik d_jl
        B_ = F @ np.transpose(F, (0, 2, 1))
        dFCF = (np.einsum("ik,tlj->tijkl", eye3, C) + np.einsum("til,tkj->tijkl", F, F)
                + np.einsum("tik,jl->tijkl", B_, eye3))
        hi2 = 2.0 * (2.0 * FF + i1[:, None, None, None, None] * np.eye(9).reshape(3, 3, 3, 3)[None] - dFCF)
        A = (2.0 * self._c10[:, None, None] * np.eye(9)[None] + self._c01[:, None, None] * hi2.reshape(-1, 9, 9)
             - self._beta[:, None, None] * dcof)
        w, v = np.linalg.eigh(A)
        A = np.einsum("tik,tk,tjk->tij", v, np.maximum(w, 0.0), v)
        ke = np.einsum("t,tai,tab,tbj->tij", self.tet_volume, self._B, A, self._B)
        k = sp.csr_matrix((ke.ravel(), (self._rows, self._cols)), shape=(3 * self.n_nodes,) * 2)
        g = np.zeros((len(self.tets), 4, 3))
        nvk.tangents(np.ascontiguousarray(x), self.tets, g)
        nt, n = len(self.tets), self.n_nodes
        rows = np.repeat(self.tets, 12, axis=1).ravel()
        cols = np.tile((3 * self.tets[:, :, None] + np.arange(3)).reshape(nt, 12), (1, 4)).ravel()
        G = sp.csr_matrix((np.tile(0.25 * g.reshape(nt, 12), (1, 4)).ravel(), (rows, cols)), shape=(n, 3 * n))
        return (k + G.T @ sp.diags(self.node_bulk / self.node_rest_volume) @ G).tocsr()

    def _newton(self, x, F_ext):
        free = np.repeat(~self.fixed, 3)
        x = x.copy()
        energy = self._energy(x, F_ext)
        # force scale of the tolerance: the load, or (unloaded) the unit-strain force of an element,
        # mu h^2, so that round-off at rest counts as converged (newton_tol x mu h^2)
        floor = float(np.mean(self.mu)) * float(np.mean(self.tet_volume)) ** (2.0 / 3.0)
        scale = max(float(np.abs(F_ext).sum()), floor, 1e-12)
        for it in range(1, self.max_iter + 1):
            r = (self._forces(x) + F_ext).ravel()[free]
            scale = max(scale, float(np.abs(self._forces(x)).sum()) * 1e-3)
            if float(np.linalg.norm(r)) <= self.newton_tol * scale:
                return True, x, it - 1
            K = self._hessian(x)[free][:, free].tocsc()
            K = K + sp.identity(K.shape[0], format="csc") * (1e-9 * float(K.diagonal().mean()))
            dx = spla.spsolve(K, r)
            slope = -float(dx @ r)
            step = 1.0
            for _ in range(30):
                trial = x.copy()
                trial.reshape(-1)[free] += step * dx
                e_t = self._energy(trial, F_ext)
                if e_t <= energy + 1e-4 * step * slope + 1e-14 * abs(energy):
                    break
                step *= 0.5
            else:
                return False, x, it
            x, energy = trial, e_t
        r = (self._forces(x) + F_ext).ravel()[free]
        return float(np.linalg.norm(r)) <= self.newton_tol * scale, x, self.max_iter

    def static_solve(self, forces=None, *, increments: int | None = None) -> np.ndarray:
        """Equilibrium (m) under ``forces`` (N,3) N + gravity with the fixed nodes at their targets,
        from the rest state in load increments (default: plate travel <= 1/4 of the shortest edge x 8);
        leaves the state there (zero velocity) and returns a copy."""
        if not self.fixed.any():
            raise ConfigError("neo_hookean.static_solve needs fixed nodes (set fixed=... or set_fixed)")
        n = self.n_nodes
        F = np.zeros((n, 3)) if forces is None else np.asarray(forces, dtype=np.float64)
        if F.shape != (n, 3) or not np.all(np.isfinite(F)):
            raise ConfigError(f"forces must be a finite ({n}, 3) array in N, got shape {F.shape}")
        F = F + self.masses[:, None] * self.gravity[None]
        start = self.rest_positions.copy()
        goal = self.fixed_targets[self.fixed]
        travel = float(np.max(np.linalg.norm(goal - start[self.fixed], axis=1), initial=0.0))
        edge = float(np.min(self.tet_volume)) ** (1.0 / 3.0)
        steps = increments or max(1, int(math.ceil(travel / (2.0 * edge))))
        # by default a failed load path is retried with 2x, 4x, 8x the increments (large strain
        # between bonded plates); an explicit ``increments`` is used as given
        for attempt in range(1 if increments else 4):
            ok, x, total, k, its = self._load_path(start, goal, F, steps)
            if ok:
                break
            failed = f"load step {k}/{steps} ({its} iterations)"
            steps *= 2
        if not ok:
            raise HyperelasticSolveError(f"neo_hookean: Newton did not converge at {failed}; use more "
                                         "increments or a finer mesh")
        self.last_newton_iterations = total
        self.positions = x
        self.velocities = np.zeros_like(x)
        return x.copy()

    def _load_path(self, start, goal, F, steps):
        """Solve ``steps`` equal load increments from ``start``: (ok, x, total iterations, step, its)."""
        x = start
        total = 0
        for k in range(1, steps + 1):
            s = k / steps
            x = x.copy()
            x[self.fixed] = start[self.fixed] + s * (goal - start[self.fixed])
            ok, x, its = self._newton(x, s * F)
            total += its
            if not ok:
                return False, x, total, k, its
        return True, x, total, steps, 0

    # ------------------------------------------------------------------------------------------
    def _advance(self, dt: float, forces: np.ndarray, stiffness) -> None:
        x0 = self.positions.copy()
        x = x0.copy()
        x[self.fixed] = self.fixed_targets[self.fixed]
        F = np.asarray(forces, dtype=np.float64) + self.masses[:, None] * self.gravity[None]
        ok, x, its = self._newton(x, F)
        if not ok:
            raise HyperelasticSolveError(f"neo_hookean: quasi-static step did not converge ({its} iterations)")
        self.last_newton_iterations = its
        self.positions = x
        self.velocities = (x - x0) / dt
        self.integrated_external_forces = np.array(forces, dtype=np.float64)

    def internal_forces(self) -> np.ndarray:
        return self._forces(self.positions)

    def elastic_energy(self) -> float:
        return self._energy(self.positions, np.zeros_like(self.positions))

    def critical_dt(self) -> float:
        return math.inf

    def stiffness_matrix(self, relaxed: bool = True, clamp: bool = False) -> sp.csr_matrix:
        """Tangent stiffness (3N x 3N, N/m) at the current state (per-tet Hessians projected PSD)."""
        return self._hessian(self.positions)
