"""Stress-induced soft-tissue growth (Vandewalle et al. 2003, section 2.3).

The basic model (section 2.1) is the linear FEM ``K u = R`` with Dirichlet conditions: bone
displacements prescribed, distant tissue fixed, ``R = 0``. Growth adds the load (eqs. 4-7)

    R = int B^T D alpha sigma_growth dV,   sigma_growth = sigma_d + sigma_g,   sigma_g = k sigma_d0^+

like a thermal expansion: ``eps_G += alpha sigma_growth`` is an eigenstrain (tensor components;
``alpha`` in 1/Pa), ``sigma_d = S(B u - eps_G)`` the stress remaining in the tissue and
``sigma_d0`` the stress of the basic model. The iteration (paper, "Iterative procedure"):

1. ``u_0``: the basic solution; ``sigma_d0 = S(B u_0)``;
2. per iteration: growth ``d eps = alpha (sigma_d + sigma_g)``, solve ``K du = f(S(d eps))`` with
   homogeneous Dirichlet conditions (K factored ONCE, sparse LU), ``u += du``, recompute ``sigma_d``;
3. stop when the growth per iteration falls below ``tol`` times the first iteration's; it reaches
   ``sigma_d = -sigma_g``. The growth of an iteration is measured by the stress its eigenstrain
   carries, ``rms |S(d eps)|`` (Pa, volume-weighted): for Hooke's law an equivalent norm of
   ``d eps``, and it ignores eigenstrains that change nothing (the averaged-nodal-pressure
   formulation's pressure-free checkerboard modes, which would otherwise stall the count).

Choices where the paper is silent (docs/models/growth.md explains and tests them):

* "``sigma_d0 > 0``" for a tensor = its principal components: ``sigma_d0^+ = sum_i max(s_i, 0)
  n_i n_i^T`` (:func:`tensile_part`). Tissue grows along the directions it is stretched and not
  along those it is compressed; the reading is frame-invariant and continuous, unlike clipping
  Voigt components (which changes with the axes) or switching the whole tensor on a scalar.
* ``sigma_g`` is made self-equilibrated (``equilibrate=True``, default): ``sigma_d`` is always in
  equilibrium, so ``sigma_d = -k sigma_d0^+`` is reachable only for the part of
  ``k sigma_d0^+`` that is; the rest would make ``u`` drift by the same amount every iteration
  forever (``equilibrate=False`` shows it). We take the self-equilibrated residual stress that
  ``k sigma_d0^+`` leaves after the mesh relaxes it elastically: ``tau - S(B v)``,
  ``K v = f(tau)`` (one more solve with the same factorisation). For the averaged-nodal-pressure
  formulation ``tau`` is first expressed in its stress space, ``S(D^-1 sigma_d0^+)`` (identity
  for Hooke's law), or its pressure-free part would also stall the iteration.
* The iteration error contracts by ``|1 - alpha lambda|`` per iteration for eigenvalues lambda of
  ``D (I - P)`` (P: compatible projection), which lie in ``[2 mu, 3 kappa]``: alpha < 2 / (3 kappa)
  = 2 (1 - 2 nu) / E always converges (``alpha_bounds``), alpha = 2 / (2 mu + 3 kappa) is the
  fastest safe value (``alpha="auto"``). E cancels from the result (only alpha E matters).

Units: m, Pa, N; alpha in 1/Pa.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse.linalg as spla

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError, GrowthDivergedError, GrowthNotConvergedError
from surgsim_envs.geometry.volume import tet_signed_volumes
from surgsim_envs.tissue.nested_dissection import dof_order, nested_dissection, node_adjacency
from surgsim_envs.tissue.growth_ops import VOIGT_ENGINEERING, ElementOperators, frobenius, tensor_to_voigt, voigt_to_tensor

#: default threshold: stop when the growth per iteration is below this fraction of the first iteration's
DEFAULT_TOL = 1e-5
#: the iteration is declared diverging when the growth per iteration exceeds this multiple of the first
DIVERGENCE_FACTOR = 1e3


def tensile_part(stress: np.ndarray) -> np.ndarray:
    """``sigma^+``: the tensile principal part of each Voigt stress (T,6) Pa (tensor shears).

    ``sigma = sum_i s_i n_i n_i^T`` (principal stresses s_i, directions n_i) ->
    ``sum_i max(s_i, 0) n_i n_i^T``. This is how the paper's "``sigma_d0 > 0``" is read."""
    stress = np.asarray(stress, dtype=np.float64)
    w, v = np.linalg.eigh(voigt_to_tensor(stress))
    return tensor_to_voigt(np.einsum("tik,tk,tjk->tij", v, np.maximum(w, 0.0), v))


def alpha_bounds(young, poisson) -> tuple[float, float]:
    """``(alpha_auto, alpha_safe)`` in 1/Pa for per-element E (Pa) and nu.

    The growth-iteration eigenvalues lie in ``[lo, hi]`` with lo, hi the extremes of 2 mu and
    3 kappa over the elements: ``alpha_safe = 2 / hi`` (every alpha below converges),
    ``alpha_auto = 2 / (lo + hi)`` (the smallest worst-case contraction factor)."""
    young = np.asarray(young, dtype=np.float64)
    poisson = np.asarray(poisson, dtype=np.float64)
    mu = young / (2.0 * (1.0 + poisson))
    kappa = young / (3.0 * (1.0 - 2.0 * poisson))
    lo = float(min(np.min(2 * mu), np.min(3 * kappa)))
    hi = float(max(np.max(2 * mu), np.max(3 * kappa)))
    return 2.0 / (lo + hi), 2.0 / hi


@dataclass
class GrowthResult:
    """Outcome of :meth:`GrowthSolver.grow`. Positions and displacements (N,3) m; Voigt stresses
    (T,6) Pa and growth strain (T,6) with tensor shear components."""

    positions: np.ndarray
    basic_positions: np.ndarray
    rest_positions: np.ndarray
    growth_strain: np.ndarray
    stress: np.ndarray
    initial_stress: np.ndarray
    growth_stress: np.ndarray
    k: float
    alpha: float
    iterations: int
    history: list = field(default_factory=list)
    factor_seconds: float = 0.0
    iterate_seconds: float = 0.0

    @property
    def displacement(self) -> np.ndarray:
        return self.positions - self.rest_positions

    @property
    def growth_displacement(self) -> np.ndarray:
        """(N,3) m: what growth adds to the basic model."""
        return self.positions - self.basic_positions


def mesh_volume(positions: np.ndarray, tets: np.ndarray) -> float:
    """Volume (m^3) of a tet mesh at ``positions``."""
    return float(np.sum(tet_signed_volumes(positions, tets)))


#: growth iterations one call may run (each is a back-substitution with the factored stiffness)
MAX_GROWTH_ITERATIONS = 100_000


class GrowthSolver:
    """Basic-model and growth solves on one mesh and one set of Dirichlet conditions.

    Parameters
    ----------
    ops: :class:`ElementOperators` of the mesh (or use :meth:`from_model`).
    stiffness: (3N,3N) rest stiffness matching ``ops`` (default ``ops.stiffness()``).
    fixed_dofs: (N,3) or (N,) bool: Dirichlet DOFs (nodes: all three DOFs).
    displacement: (N,3) m prescribed displacements at those DOFs (bone motion); default zero.
    name: model name for error messages.
    """

    def __init__(self, ops: ElementOperators, stiffness=None, fixed_dofs=None, displacement=None,
                 name: str = "fem"):
        self.ops = ops
        self.name = name
        n = ops.n_nodes
        self.rest_positions = ops.nodes
        mask = np.zeros((n, 3), dtype=bool) if fixed_dofs is None else np.asarray(fixed_dofs, dtype=bool)
        if mask.shape == (n,):
            mask = np.repeat(mask[:, None], 3, axis=1)
        if mask.shape != (n, 3):
            raise ConfigError(f"fixed_dofs must be a bool array of shape ({n},) or ({n}, 3), got {mask.shape}")
        if not mask.any():
            raise ConfigError("growth needs Dirichlet conditions: with no fixed DOF the stiffness K is singular "
                              "(rigid-body modes). Fix the bone-contact and distant nodes (model.set_fixed(...)).")
        disp = np.zeros((n, 3)) if displacement is None else np.asarray(displacement, dtype=np.float64)
        if disp.shape != (n, 3) or not np.all(np.isfinite(disp)):
            raise ConfigError(f"displacement must be a finite (N,3) array in m with N={n}, got shape {disp.shape}")
        self.fixed = mask.ravel()
        self.free = ~self.fixed
        self.prescribed = np.where(mask, disp, 0.0).ravel()
        k = ops.stiffness() if stiffness is None else stiffness
        self.stiffness = k.tocsr()
        self._kfd = self.stiffness[self.free][:, self.fixed]
        self._lu = None
        self.factorizations = 0
        self.factor_seconds = 0.0
        self._basic = None

    @classmethod
    def from_model(cls, model, fixed_dofs=None, displacement=None) -> "GrowthSolver":
        """Solver on a :class:`~surgsim_envs.tissue.fem.TetFEMModel`: its rest mesh, materials,
        formulation and rest stiffness. Dirichlet conditions default to the model's fixed nodes
        and their targets (``set_fixed(nodes, targets)``: targets - rest = prescribed displacement).
        Growth is linear (the paper's small-strain model): corotation is not used, and K is the rest
        stiffness of the current material fields, assembled from the same element operators."""
        if fixed_dofs is None:
            fixed_dofs = model.fixed.copy()
            if displacement is None:
                displacement = model.fixed_targets - model.rest_positions
        ops = ElementOperators.from_model(model)
        return cls(ops, ops.stiffness(), fixed_dofs, displacement, name=model.name)

    # ------------------------------------------------------------------------------------------
    def factor(self):
        """Sparse LU of the free-DOF block of K (once), in a geometric nested-dissection order."""
        if self._lu is None:
            t0 = time.perf_counter()
            order = nested_dissection(self.rest_positions, node_adjacency(self.ops.tets, self.ops.n_nodes), leaf=16)
            perm = dof_order(order, self.free)
            kff = self.stiffness[self.free][:, self.free]
            kp = kff[perm][:, perm].tocsc()
            try:
                lu = spla.splu(kp, permc_spec="NATURAL", diag_pivot_thresh=0.0, options=dict(SymmetricMode=True))
            except RuntimeError as exc:
                raise ConfigError(f"growth: the stiffness K is singular ({exc}); the Dirichlet conditions do not hold "
                                  "the body (fix nodes so no rigid motion remains)") from None
            piv = np.abs(lu.U.diagonal())
            if not np.all(np.isfinite(piv)) or piv.min() <= 1e-10 * piv.max():
                raise ConfigError(f"growth: the stiffness K is singular (pivot ratio {piv.min() / piv.max():.2g}): "
                                  "the Dirichlet conditions leave a rigid-body motion free; fix at least three "
                                  "non-collinear nodes, or whole faces")
            self._lu, self._perm = lu, perm
            self.factorizations += 1
            self.factor_seconds = time.perf_counter() - t0
        return self._lu

    def _solve_free(self, rhs_free: np.ndarray) -> np.ndarray:
        lu = self.factor()
        out = np.empty_like(rhs_free)
        out[self._perm] = lu.solve(rhs_free[self._perm])
        return out

    def basic(self) -> np.ndarray:
        """(3N,) displacement (m) of the basic model: ``K u = 0`` with the prescribed displacements."""
        if self._basic is None:
            u = self.prescribed.copy()
            u[self.free] = self._solve_free(-(self._kfd @ self.prescribed[self.fixed]))
            self._basic = u
        return self._basic.copy()

    def equilibrated(self, tau: np.ndarray) -> np.ndarray:
        """Self-equilibrated part of a Voigt stress field (T,6) Pa: ``tau - S(B v)``, ``K v = f(tau)``
        on the free DOFs (v = 0 on the Dirichlet DOFs)."""
        v = np.zeros(3 * self.ops.n_nodes)
        v[self.free] = self._solve_free(self.ops.forces(tau)[self.free])
        return tau - self.ops.stress(self.ops.strain(v))

    def alpha_bounds(self) -> tuple[float, float]:
        """``(alpha_auto, alpha_safe)`` (1/Pa) of this mesh's materials (see :func:`alpha_bounds`)."""
        return alpha_bounds(self.ops.young, self.ops.poisson)

    def growth_operator(self, s: np.ndarray) -> np.ndarray:
        """``M s``: the stress change per unit alpha when the tissue grows by ``eps_G = s`` (Voigt, tensor
        shears) with homogeneous Dirichlet conditions; the iteration is ``s <- (I - alpha M) s``."""
        eps = VOIGT_ENGINEERING * s
        v = np.zeros(3 * self.ops.n_nodes)
        v[self.free] = self._solve_free(self.ops.forces(self.ops.stress(eps))[self.free])
        return self.ops.stress(eps - self.ops.strain(v))

    def spectral_alpha_limit(self, iterations: int = 60, seed: int = 0) -> float:
        """Divergence threshold ``2 / lambda_max(M)`` (1/Pa) of this mesh, lambda_max by power
        iteration (Rayleigh quotient in the tensor inner product, a lower bound that converges from
        below, so the returned limit converges from above). Costs one solve per iteration."""
        s = self.growth_operator(np.random.default_rng(seed).normal(size=(self.ops.n_elements, 6)))
        lam = 0.0
        for _ in range(iterations):
            w = self.growth_operator(s)
            lam = self._dot(s, w) / self._dot(s, s)
            s = w / math.sqrt(self._dot(w, w))
        return 2.0 / lam

    def _dot(self, a: np.ndarray, b: np.ndarray) -> float:
        prod = np.sum(a[:, :3] * b[:, :3], axis=1) + 2.0 * np.sum(a[:, 3:] * b[:, 3:], axis=1)
        return float(np.sum(self.ops.volume * prod))

    def rms(self, voigt_tensor: np.ndarray) -> float:
        """Volume-weighted RMS of the Frobenius norm of a Voigt tensor field (tensor shears)."""
        v = self.ops.volume
        return float(math.sqrt(np.sum(v * frobenius(voigt_tensor) ** 2) / np.sum(v)))

    # ------------------------------------------------------------------------------------------
    def grow(self, k: float = 20.0, alpha="auto", *, tol: float = DEFAULT_TOL, max_iter: int = 500,
             equilibrate: bool = True, callback=None) -> GrowthResult:
        """Run the growth iteration; returns a :class:`GrowthResult`.

        k: growth parameter (>= 0; 0 = growth only relieves the displacement stress).
        alpha: stability factor in 1/Pa (> 0) or "auto" (:meth:`alpha_bounds`).
        tol: stop when the growth per iteration (rms stress of its eigenstrain) <= tol x the first
            iteration's (0 < tol < 1).
        max_iter: iteration cap; reaching it raises GrowthNotConvergedError (slow) or
            GrowthDivergedError (growing). Growth above DIVERGENCE_FACTOR x the first
            iteration's, or a non-finite value, raises GrowthDivergedError at once.
        equilibrate: make sigma_g self-equilibrated (module doc); False = the paper's literal k sigma_d0^+.
        callback: optional ``callback(iteration, growth)`` after each iteration (progress bars).
        """
        k = validate.non_negative(k, "k (growth parameter)", fix="k >= 0 scales the extra growth; the paper's optimum is 20")
        auto, safe = self.alpha_bounds()
        if isinstance(alpha, str):
            if alpha != "auto":
                raise ConfigError(f"alpha must be a positive number (1/Pa) or 'auto', got {alpha!r}")
            alpha = auto
        alpha = validate.positive(alpha, "alpha (stability factor, 1/Pa)",
                                  fix=f"use alpha='auto' ({auto:.4g} 1/Pa here) or a value below {safe:.4g} 1/Pa")
        tol = validate.real(tol, "tol", lo=0.0, hi=1.0, lo_open=True, hi_open=True,
                            fix="e.g. 1e-5 (relative growth per iteration)")
        validate.integer(max_iter, "max_iter", lo=1, hi=MAX_GROWTH_ITERATIONS,
                         fix=f"iterations of the growth loop, at most {MAX_GROWTH_ITERATIONS:,} (each is a solve)")
        ops = self.ops
        t0 = time.perf_counter()
        self.factor()
        u = self.basic()
        basic = u.copy()
        sig0 = ops.stress(ops.strain(u))
        tens = ops.in_stress_space(tensile_part(sig0))
        sig_g = k * (self.equilibrated(tens) if (equilibrate and k > 0) else tens)
        eps_g = np.zeros_like(sig0)            # Voigt, tensor shears
        sig_d = sig0
        history: list[float] = []
        converged = False
        for it in range(1, max_iter + 1):
            d_eps = alpha * (sig_d + sig_g)
            d_sig = ops.stress(VOIGT_ENGINEERING * d_eps)      # stress carried by this iteration's growth
            g = self.rms(d_sig)
            history.append(g)
            if not math.isfinite(g):
                raise GrowthDivergedError(self.name, alpha, safe, it, "the growth became non-finite")
            if history[0] == 0.0:              # no stress at all: nothing grows
                history.pop()
                converged = True
                break
            if g > DIVERGENCE_FACTOR * history[0]:
                raise GrowthDivergedError(self.name, alpha, safe, it,
                                          f"growth per iteration {g:.3g} > {DIVERGENCE_FACTOR:g} x the first ({history[0]:.3g})")
            du = ops.forces(d_sig)
            u[self.free] += self._solve_free(du[self.free])
            eps_g += d_eps
            sig_d = ops.stress(ops.strain(u) - VOIGT_ENGINEERING * eps_g)
            if callback is not None:
                callback(it, g)
            if g <= tol * history[0]:
                converged = True
                break
        if not converged:
            tail = history[-6:]
            rate = (tail[-1] / tail[0]) ** (1.0 / max(len(tail) - 1, 1)) if tail[0] > 0 else float("nan")
            if abs(rate - 1.0) < 1e-3:
                raise GrowthNotConvergedError(
                    f"tissue growth stalled: after max_iter={max_iter} iterations (alpha={alpha:.4g} 1/Pa, k={k:g}) the "
                    f"growth per iteration stays at {history[-1] / history[0]:.3g} of the first (tol={tol:g}). Either "
                    f"alpha sits at the divergence threshold (about {safe:.4g} 1/Pa: use alpha='auto', {auto:.4g}) or "
                    "part of the growth load can be balanced by no displacement, so the tissue drifts by the same "
                    "amount every iteration (equilibrate=False: use equilibrate=True, the default)")
            if not rate < 1.0:
                raise GrowthDivergedError(self.name, alpha, safe, len(history),
                                          f"the growth per iteration grows by x{rate:.4f} per iteration")
            need = len(history) + math.log(tol * history[0] / history[-1]) / math.log(rate)
            raise GrowthNotConvergedError(
                f"tissue growth did not converge in max_iter={max_iter} iterations (alpha={alpha:.4g} 1/Pa, k={k:g}): "
                f"growth per iteration fell to {history[-1] / history[0]:.3g} of the first, contracting x{rate:.4f} per "
                f"iteration; about {need:.0f} iterations are needed for tol={tol:g}. Raise max_iter, or use "
                f"alpha='auto' ({auto:.4g} 1/Pa)")
        rest = self.rest_positions
        return GrowthResult(positions=rest + u.reshape(-1, 3), basic_positions=rest + basic.reshape(-1, 3),
                            rest_positions=rest.copy(), growth_strain=eps_g, stress=sig_d, initial_stress=sig0,
                            growth_stress=sig_g, k=k, alpha=alpha, iterations=len(history), history=history,
                            factor_seconds=self.factor_seconds, iterate_seconds=time.perf_counter() - t0)


def grow(model, k: float = 20.0, alpha="auto", *, fixed_dofs=None, displacement=None, **kwargs) -> GrowthResult:
    """Grow a :class:`~surgsim_envs.tissue.fem.TetFEMModel` (see :class:`GrowthSolver`).

    Dirichlet conditions default to the model's fixed nodes and targets. Sets ``model.positions``
    to the grown equilibrium (velocities zero) and returns the :class:`GrowthResult`."""
    solver = GrowthSolver.from_model(model, fixed_dofs, displacement)
    res = solver.grow(k, alpha, **kwargs)
    model.positions = res.positions.copy()
    model.velocities = np.zeros_like(model.positions)
    return res
