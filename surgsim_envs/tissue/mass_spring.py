"""Nonlinear viscoelastic mass-spring-damper tissue (the grasping simulation paper, eqs. 1-3).

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

The plain network (the grasping simulation paper, the default) lets the tets under a node that carries a concentrated
load collapse flat: over a stiff inclusion the surface node under a palpation probe snaps sideways
off the tip and the probe reads less force than beside it. ``volume_stiffness="capped"`` (the model's
``point_load_options``, which the palpation tasks build it with) adds a per-tet volume term: springs
scaled and ``k_v`` set so that the small-strain modulus is E and the Poisson ratio min(nu,
CAPPED_POISSON = 0.123), the largest whose P-wave modulus (which sets the explicit step) is the plain
network's. Where a scene steps the model implicitly anyway (a stiff inclusion on a fine lattice),
that cap buys nothing and is too weak: a press deeper than the lattice spacing pushes the surface
node through the layer below and inverts its tets, and a stiffer layer below then *lowers* the force.
There the model's ``implicit_point_load_options`` (``volume_stiffness="auto"``, the material's own
nu) apply. See docs/models/mass_spring.md.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, Mapping

import numpy as np
from numba import njit

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError, StaticSolveError
from surgsim_envs.tissue import msd_kernels as kern
from surgsim_envs.tissue.base import TissueModel

#: c in k_ij = c * sum_t E_t V_t / L0^2 (see module docstring and docs/models/mass_spring.md)
EDGE_STIFFNESS_FACTOR = 1.0
#: alpha in K2 = alpha * nonlinear * K1 / (3 L0^2). A spring at angle theta to a uniaxial strain eps
#: sees eps cos^2(theta); averaging the quartic energy over isotropic directions (<cos^4>/<cos^8> = 9/5)
#: makes the tissue-level tangent stiffness grow as k0 (1 + nonlinear * eps^2), as Material describes.
NONLINEAR_NETWORK_FACTOR = 9.0 / 5.0
#: the spring network's own small-strain constants on the box lattice (Kuhn split), per unit E
#: (measured: axial modulus 1.034 E, Poisson ratio 0.03; docs/models/mass_spring.md)
NETWORK_YOUNG_FACTOR = 1.034
NETWORK_POISSON = 0.03
#: network Lame constants per unit E: mu_n = E_n / (2 (1 + nu_n)), lambda_n = E_n nu_n / ((1 + nu_n)(1 - 2 nu_n))
NETWORK_SHEAR_FACTOR = NETWORK_YOUNG_FACTOR / (2.0 * (1.0 + NETWORK_POISSON))
NETWORK_LAMBDA_FACTOR = NETWORK_YOUNG_FACTOR * NETWORK_POISSON / ((1.0 + NETWORK_POISSON) * (1.0 - 2.0 * NETWORK_POISSON))
#: P-wave modulus lambda_n + 2 mu_n of the plain network per unit E (it sets the explicit step's limit)
NETWORK_PWAVE_FACTOR = NETWORK_LAMBDA_FACTOR + 2.0 * NETWORK_SHEAR_FACTOR
#: the largest Poisson ratio whose P-wave modulus E (1 - nu) / ((1 + nu)(1 - 2 nu)) does not exceed the plain
#: network's (the root of 2 m nu^2 + (m - 1) nu - (m - 1) = 0, m = NETWORK_PWAVE_FACTOR): the default volume
#: term ("capped") matches the material's E and min(nu, CAPPED_POISSON) without shortening the explicit step
CAPPED_POISSON = (-(NETWORK_PWAVE_FACTOR - 1.0) + math.sqrt((NETWORK_PWAVE_FACTOR - 1.0) ** 2
                  + 8.0 * NETWORK_PWAVE_FACTOR * (NETWORK_PWAVE_FACTOR - 1.0))) / (4.0 * NETWORK_PWAVE_FACTOR)
#: relative residual at which the implicit step's conjugate gradients stop
CG_TOLERANCE = 1e-6
#: iteration cap of the implicit step's conjugate gradients
CG_MAX_ITER = 500
#: static solve: Newton iterations per load increment the increment control aims at (the next
#: increment grows by up to 2x when fewer were needed, shrinks by up to 2x when more)
STATIC_TARGET_ITERATIONS = 6
#: static solve: smallest load increment (fraction of the load) before it reports failure
STATIC_MIN_INCREMENT = 1.0 / 4096
#: static solve: Armijo constant of the line search (energy, or residual norm where the energy's
#: rounding cannot resolve the predicted decrease)
ARMIJO = 1e-4
#: relative rounding level of the summed energy: a predicted decrease below this many ulps of
#: the energy scale is judged on the residual norm instead (the energy cannot see it)
ENERGY_NOISE_ULPS = 1e4


@njit(cache=True, nogil=True)
def _finite_non_negative(a) -> bool:
    """All entries of the 1-D array ``a`` finite and >= 0 (the contact-stiffness check, no temporaries)."""
    for i in range(a.shape[0]):
        v = a[i]
        if not (np.isfinite(v) and v >= 0.0):
            return False
    return True


def _count_inverted(x: np.ndarray, tets: np.ndarray) -> int:
    """Number of tets with non-positive signed volume at positions x (N,3) m."""
    e = x[tets[:, 1:]] - x[tets[:, :1]]
    return int(np.count_nonzero(np.linalg.det(e) <= 0.0))


#: the fix quoted when a spring constant K1 is not > 0, and when another override is negative
_K1_FIX = "it is a spring constant in N/m (leave it None to derive it from the material's Young's modulus)"
_NON_NEGATIVE_FIX = "negative stiffness or damping injects energy; leave it None to derive it from the material"


def _check_scalar(name: str, value: Any, *, positive: bool) -> float:
    """``value`` as a float: > 0 if ``positive`` (K1), else >= 0 (:mod:`surgsim_envs.validate`)."""
    if positive:
        return validate.positive(value, f"mass_spring: {name}", fix=_K1_FIX)
    return validate.non_negative(value, f"mass_spring: {name}", fix=_NON_NEGATIVE_FIX)


class MassSpringModel(TissueModel):
    """Nonlinear viscoelastic mass-spring-damper model on the tet edges (the grasping simulation paper).

    Parameters
    ----------
    volume, material: see :class:`TissueModel`. Per-tet fields (``self.fields``) set the springs
        and the volume term, so region materials (inclusions) make the springs and tets around them stiffer.
    integrator: "auto" (default: "symplectic" while dt <= :meth:`stable_dt` (DT_SAFETY x critical_dt), else
        "implicit"; see :meth:`TissueModel.choose_integrator`), "symplectic" (semi-implicit Euler,
        explicit: dt < :meth:`critical_dt`) or "implicit" (backward Euler, one Newton step,
        conjugate gradients; stable at 1 ms).
    springs: "edges" (one spring per unique tet edge; the only layout so far).
    K1: long-term linear spring constant (N/m) for every spring, overriding the E-mapping.
    K2: cubic spring coefficient (N/m^3) for every spring, overriding ``nonlinear``.
    b0: nodal damping (N s/m) for every node, overriding ``damping * m_i``.
    b1: Maxwell dashpot (N s/m) for every spring, overriding ``kM * relax_time``; needs
        ``relax_fraction > 0`` (the branch spring ``kM = g1/(1-g1) K1``).
    The overrides may also come from ``material.extra`` ({"K1": ..., ...}); keywords win.
    volume_stiffness: optional per-tet volume-preservation term (Teschner et al. 2004),
        ``E_t = 0.5 k_v (V - V0)^2 / V0``: None (off, the default: the grasping simulation paper's plain spring network,
        whose tets under a concentrated load can collapse flat), a number k_v >= 0 in Pa (springs
        unchanged), "auto" or "capped": springs scaled by mu / mu_network and k_v = lambda - scale *
        lambda_network per tet, so that the network's small-strain (E, nu) on the box lattice match the
        material's E and its nu ("auto") or min(nu, CAPPED_POISSON) ("capped": the explicit step's limit
        stays the plain network's; ``point_load_options``). See docs/models/mass_spring.md.
    **base_kwargs: region_materials, fixed, gravity, guard (see :class:`TissueModel`).
    """

    name: ClassVar[str] = "mass_spring"
    compiled_step_module: ClassVar[str | None] = "surgsim_envs.tissue.mass_spring_compiled"
    summary: ClassVar[str] = ("nonlinear viscoelastic mass-spring-damper on tet edges (the grasping simulation paper): "
                              "cubic springs + Maxwell branches (+ optional volume term), auto/symplectic/implicit")
    integrators: ClassVar[tuple[str, ...]] = ("symplectic", "implicit")
    auto_pair: ClassVar[tuple[str, str] | None] = ("symplectic", "implicit")
    default_integrator: ClassVar[str | None] = "auto"
    capabilities: ClassVar[frozenset[str]] = frozenset(
        {"forces", "unstructured_mesh", "implicit_contact", "viscoelastic", "static_solve", "subsurface_stiffness"})
    material_fields: ClassVar[tuple[str, ...]] = ("young", "poisson", "density", "damping", "relax_fraction",
                                                  "relax_time", "nonlinear")
    #: a probe pressing one surface node collapses the plain network's tets (module docstring): the
    #: capped volume term keeps them, at the plain network's explicit step
    point_load_options: ClassVar[Mapping[str, Any]] = {"volume_stiffness": "capped"}
    #: stepped implicitly (a stiff inclusion on a fine lattice), the explicit limit that capped nu no longer
    #: binds, and the capped term is too weak there: a press deeper than the lattice spacing pushes the
    #: surface node through the layer below, inverting its tets (docs/models/mass_spring.md)
    implicit_point_load_options: ClassVar[Mapping[str, Any]] = {"volume_stiffness": "auto"}

    def __init__(self, volume, material="liver", *, integrator=None, springs="edges",
                 K1=None, K2=None, b0=None, b1=None, volume_stiffness=None, cg_tol: float = CG_TOLERANCE,
                 **base_kwargs):
        validate.real(cg_tol, "mass_spring: cg_tol", lo=0.0, hi=1.0, lo_open=True, hi_open=True,
                      fix="it is the relative CG residual, e.g. 1e-6")
        if springs != "edges":
            raise ConfigError(f"mass_spring: springs={springs!r} is not supported; use springs='edges' "
                              "(one spring per tet edge)")
        super().__init__(volume, material, integrator=integrator, **base_kwargs)
        extra = dict(self.material.extra or {})
        overrides = {}
        for key, value in (("K1", K1), ("K2", K2), ("b0", b0), ("b1", b1)):
            value = extra.get(key) if value is None else value
            overrides[key] = None if value is None else _check_scalar(key, value, positive=(key == "K1"))
        self._overrides = overrides
        self._setup_volume_term(volume_stiffness)
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
        self._cg: list[np.ndarray] | None = None   # implicit work buffers, allocated on first use
        #: relative residual at which the implicit step's conjugate gradients stop (the momentum
        #: handed to the tools is exact up to this residual)
        self.cg_tol = float(cg_tol)
        self.last_cg_iterations = 0

    # ---------------------------------------------------------------------------------------
    # Parameters
    def _build_springs(self, overrides: dict[str, float | None]) -> None:
        vol = self.volume
        n = vol.n_nodes
        if not hasattr(self, "_edge_of"):
            self._edge_topology()
        edges = self.springs
        self.si = np.ascontiguousarray(edges[:, 0])
        self.sj = np.ascontiguousarray(edges[:, 1])
        X = self.rest_positions
        L0 = np.linalg.norm(X[self.sj] - X[self.si], axis=1)
        if np.any(L0 <= 0):
            raise ConfigError(f"mass_spring: volume '{vol.name}' has coincident nodes (zero-length edge); merge them")
        self.rest_lengths = L0

        # tets around each edge: k_e = c * sum_t E_t V_t / L0^2; other fields E V-weighted means
        tets = vol.tets.astype(np.int64)
        edge_of = self._edge_of
        f = self.fields
        tet_vol = self._tet_vol
        w_tet = f["young"] * tet_vol
        w = np.repeat(w_tet, 6)
        ne = len(edges)
        wsum = np.bincount(edge_of, weights=w, minlength=ne)

        def mean(field: str) -> np.ndarray:
            return np.bincount(edge_of, weights=w * np.repeat(f[field], 6), minlength=ne) / wsum

        if self.volume_stiffness in ("auto", "capped"):   # springs carry the shear modulus only
            wk = np.bincount(edge_of, weights=np.repeat(w_tet * self._shear_scale, 6), minlength=ne)
        else:
            wk = wsum
        k = EDGE_STIFFNESS_FACTOR * wk / L0 ** 2
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

    def _edge_topology(self) -> None:
        """Springs (unique tet edges), the edge of each tet's six edges, tet volumes (built once)."""
        vol = self.volume
        n = vol.n_nodes
        edges = vol.edges().astype(np.int64)
        self.springs = edges
        tets = vol.tets.astype(np.int64)
        pairs = np.sort(np.stack([tets[:, [0, 0, 0, 1, 1, 2]].ravel(), tets[:, [1, 2, 3, 2, 3, 3]].ravel()], axis=1), axis=1)
        self._edge_of = np.searchsorted(edges[:, 0] * n + edges[:, 1], pairs[:, 0] * n + pairs[:, 1])
        self._tet_vol = vol.tet_volumes()

    def _on_material_changed(self, name: str) -> None:
        """Re-derive springs, dashpots, the volume term and masses from the per-tet fields
        (contract v2 ``scale_material`` / ``set_field``; about 0.1-1 ms for 1k nodes). The Maxwell
        branch state (force s) is kept: a change between episodes follows a reset anyway."""
        if name == "relax_fraction" and np.any((self.fields[name] < 0) | (self.fields[name] >= 1)):
            raise ConfigError("relax_fraction must lie in [0, 1) in every element")
        if name in ("young", "relax_time") and np.any(self.fields[name] <= 0):
            raise ConfigError(f"{name} must be > 0 in every element")
        if self.volume_stiffness is not None:
            self._setup_volume_term(self.volume_stiffness)
        self._build_springs(self._overrides)
        self.inv_mass = 1.0 / self.masses
        self._coeff_cache = {}     # coefficients of the old springs (_apply_field then calls notify_changed())

    def _setup_volume_term(self, volume_stiffness) -> None:
        """Per-tet volume stiffness ``volume_kv`` (Pa) and rest volumes ``volume_rest`` (m^3)."""
        tets = np.ascontiguousarray(self.volume.tets, dtype=np.int64)
        nt = len(tets)
        self._shear_scale = np.ones(nt)
        if volume_stiffness is None:
            self.volume_stiffness = None
            self._vtets = np.zeros((0, 4), dtype=np.int64)
            self.volume_kv = np.zeros(0)
            self.volume_rest = np.ones(0)
            return
        if isinstance(volume_stiffness, str):
            if volume_stiffness not in ("auto", "capped"):
                raise ConfigError(f"mass_spring: volume_stiffness={volume_stiffness!r} must be None (off), 'auto' (the "
                                  "material's E and Poisson ratio), 'capped' (its E and Poisson ratio up to "
                                  f"{CAPPED_POISSON:.3f}) or a stiffness k_v >= 0 in Pa")
            E, nu = self.fields["young"], self.fields["poisson"]
            if np.any(nu >= 0.5) or np.any(nu <= -1.0):
                raise ConfigError(f"mass_spring: volume_stiffness={volume_stiffness!r} needs -1 < poisson < 0.5 in "
                                  "every region")
            if volume_stiffness == "capped":
                nu = np.minimum(nu, CAPPED_POISSON)
            mu = E / (2.0 * (1.0 + nu))
            lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
            self._shear_scale = mu / (NETWORK_SHEAR_FACTOR * E)
            kv = np.maximum(lam - self._shear_scale * NETWORK_LAMBDA_FACTOR * E, 0.0)
            self.volume_stiffness = volume_stiffness
        else:
            value = _check_scalar("volume_stiffness", volume_stiffness, positive=False)
            kv = np.full(nt, value)
            self.volume_stiffness = value
        v0 = np.empty(nt)     # by the energy kernel's arithmetic: the rest state is exactly unloaded
        kern.tet_volumes(np.ascontiguousarray(self.rest_positions, dtype=np.float64), tets, v0)
        if np.any(v0 <= 0):
            raise ConfigError(f"mass_spring: volume '{self.volume.name}' has {int(np.sum(v0 <= 0))} tets with "
                              "non-positive rest volume; the volume term needs positively oriented tets")
        self._vtets = tets
        self.volume_kv = np.ascontiguousarray(kv, dtype=np.float64)
        self.volume_rest = np.ascontiguousarray(v0)

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
            self._coeff_cache = {}
            self.notify_changed()      # the arrays it held are replaced
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
            if kc.shape != (self.n_nodes,) or not _finite_non_negative(kc):
                raise ConfigError(f"stiffness must be a finite, non-negative ({self.n_nodes},) array in N/m, "
                                  f"got shape {np.shape(stiffness)}")
        if self.active_integrator == "symplectic":
            kern.symplectic_step_work(self.positions, self.velocities, self.inv_mass, self.b0, fext, self.gravity,
                                      self.fixed, dt, self.si, self.sj, self.rest_lengths, self.K1, self.K2, kMg,
                                      decay, self._s, self._dl, self._f, self._vtets, self.volume_rest,
                                      self.volume_kv, self.spring_work())
        else:
            kMg_next, _ = self._branch_coeffs(dt)
            if self._cg is None:
                self._allocate_implicit_buffers()
            r, z, p, ap, pre = self._cg
            self.last_cg_iterations = kern.implicit_step(
                self.positions, self.velocities, self.masses, self.b0, fext, self.gravity, self.fixed, kc, dt,
                self.si, self.sj, self.rest_lengths, self.K1, self.K2, kMg, decay, kMg_next, self._s, self._dl,
                self._f, self._coef_a, self._coef_g, self._unit, self._diag, pre, r, z, p, ap,
                self.cg_tol, CG_MAX_ITER, self._vtets, self.volume_rest, self.volume_kv, self._vgrad, self._vcoef)
            if stiffness is not None:   # backward Euler integrated f_ext - kc (x_{n+1} - x_n) = f_ext - dt kc v_{n+1}
                free = ~self.fixed
                self.integrated_external_forces[free] -= (dt * kc[free])[:, None] * self.velocities[free]
        self._pending_dt = dt

    def symplectic_kernel_state(self, dt: float) -> tuple:
        """The arguments of :func:`surgsim_envs.tissue.msd_kernels.symplectic_step` for steps of
        ``dt`` s from the current state, for a compiled caller that steps the model itself (the
        scene's compiled substeps, registered for integrator "symplectic"): ``(positions,
        velocities, inv_mass, b0, gravity, fixed, si, sj, L0, K1, K2, kMg_first, decay_first, kMg,
        decay, s, dl, f_buf, tets, V0, kv)``. The Maxwell-branch coefficients of the first step
        span the interval since the last commit (as :meth:`step` uses them), those of the others
        span ``dt``. The arrays are the model's own; valid until the next reset(), material change or
        static_solve() (which replace them)."""
        kMg0, decay0 = self._branch_coeffs(self._pending_dt)
        kMg, decay = self._branch_coeffs(float(dt))
        return (self.positions, self.velocities, self.inv_mass, self.b0, self.gravity, self.fixed, self.si, self.sj,
                self.rest_lengths, self.K1, self.K2, kMg0, decay0, kMg, decay, self._s, self._dl, self._f,
                self._vtets, self.volume_rest, self.volume_kv)

    def spring_work(self) -> np.ndarray:
        """The (4, springs) float64 work buffer of the symplectic spring pass
        (:func:`~surgsim_envs.tissue.msd_kernels.symplectic_step_work`), allocated once per spring count."""
        w = getattr(self, "_spring_work", None)
        if w is None or w.shape[1] != len(self.si):
            w = self._spring_work = np.empty((4, len(self.si)))
            self.notify_changed()
        return w

    def committed_symplectic_steps(self, dt: float) -> None:
        """Bookkeeping after a compiled caller advanced the model with :meth:`symplectic_kernel_state`
        (at least one step of ``dt``): the branches are now committed at an interval of ``dt``."""
        self._pending_dt = float(dt)

    def _allocate_implicit_buffers(self) -> None:
        n, ne = self.n_nodes, self.n_springs
        self._coef_a = np.zeros(ne)
        self._coef_g = np.zeros(ne)
        self._unit = np.zeros((ne, 3))
        self._diag = np.zeros(n)
        self._cg = [np.zeros((n, 3)) for _ in range(5)]
        self._vgrad = np.zeros((len(self._vtets), 4, 3))
        self._vcoef = np.zeros(len(self._vtets))
        self.notify_changed()

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

    def volume_forces(self, positions: np.ndarray | None = None) -> np.ndarray:
        """(N,3) nodal forces (N) of the volume term at ``positions`` (default current; zero if off)."""
        x = self.positions if positions is None else np.ascontiguousarray(positions, dtype=np.float64)
        out = np.zeros_like(x)
        kern.volume_forces(x, self._vtets, self.volume_rest, self.volume_kv, out)
        return out

    def volume_energy(self, positions: np.ndarray | None = None) -> float:
        """Energy (J) of the volume term, sum 0.5 k_v (V - V0)^2 / V0 (0 if off)."""
        x = self.positions if positions is None else np.ascontiguousarray(positions, dtype=np.float64)
        return float(kern.volume_energy(x, self._vtets, self.volume_rest, self.volume_kv))

    def internal_forces(self) -> np.ndarray:
        """(N,3) springs + Maxwell branches + volume term + nodal damping ``-b0 v`` (N) at the current state."""
        f = self.spring_forces() - self.b0[:, None] * self.velocities
        if len(self._vtets):
            kern.volume_forces(self.positions, self._vtets, self.volume_rest, self.volume_kv, f)
        return f

    def node_stress(self) -> np.ndarray:
        """(N,) Pa von Mises stress per node from the virial of its springs:
        ``sigma_i = 1/(2 V_i) sum_{e at i} f_e d_e d_e^T / |d_e|`` (f_e the spring tension incl. the
        Maxwell branch, V_i the node's share of the tet volume); hydrostatic parts (the volume term)
        do not enter the von Mises measure."""
        x = self.positions
        d = x[self.sj] - x[self.si]
        ln = np.linalg.norm(d, axis=1)
        dl = ln - self.rest_lengths
        f = self.K1 * dl + self.K2 * dl ** 3 + self.branch_forces()
        outer = ((f / np.maximum(ln, 1e-300))[:, None, None] * d[:, :, None] * d[:, None, :]).reshape(-1, 9)
        n = self.n_nodes
        if getattr(self, "_vnode", None) is None:
            self._vnode = np.bincount(self.volume.tets.reshape(-1), weights=np.repeat(np.abs(self._tet_vol) / 4.0, 4),
                                      minlength=n)
        sig = np.empty((n, 9))
        for k in range(9):
            sig[:, k] = (np.bincount(self.si, weights=outer[:, k], minlength=n)
                         + np.bincount(self.sj, weights=outer[:, k], minlength=n))
        sig = sig.reshape(n, 3, 3) / (2.0 * self._vnode)[:, None, None]
        from surgsim_envs.tissue.base import von_mises
        return von_mises(sig)

    def elastic_energy(self) -> float:
        """Energy (J) in the springs (0.5 K1 dl^2 + 0.25 K2 dl^4), Maxwell springs (s^2 / 2 kM) and
        the volume term (0.5 k_v (V - V0)^2 / V0)."""
        kMg, decay = self._branch_coeffs(self._pending_dt)
        return float(kern.elastic_energy(self.positions, self.si, self.sj, self.rest_lengths, self.K1, self.K2,
                                         self.kM, kMg, decay, self._s, self._dl)) + self.volume_energy()

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
                                               self.K1, self.K2, self.kM, self._s, self._dl, decay, kMg,
                                               self._vtets, self.volume_rest, self.volume_kv))
        beta = float(np.max(self.b0 * self.inv_mass)) if self.n_nodes else 0.0
        if lam <= 0:
            return math.inf if beta == 0 else 2.0 / beta
        return (-beta + math.sqrt(beta * beta + 4.0 * lam)) / lam   # no safety factor: see stable_dt()

    def stiffness_matrix(self, relaxed: bool = False, clamp: bool = False):
        """Tangent stiffness ``-df/dx`` (scipy.sparse CSR, 3N x 3N, N/m, dof = 3 * node + axis).

        relaxed: long-term stiffness (Maxwell branches relaxed away); else the instantaneous one.
        clamp: drop compressive geometric stiffness so the matrix is positive semi-definite.
        """
        return self._tangent(self.positions, relaxed, clamp)

    def _tangent(self, positions: np.ndarray, relaxed: bool, clamp: bool):
        """:meth:`stiffness_matrix` at ``positions`` (N,3) m."""
        import scipy.sparse as sp

        ne = self.n_springs
        a, g, u = np.empty(ne), np.empty(ne), np.empty((ne, 3))
        if relaxed:
            kern.spring_tangents(positions, self.si, self.sj, self.rest_lengths, self.K1, self.K2,
                                 np.zeros(ne), np.zeros(ne), clamp, a, g, u)
        else:
            kern.spring_tangents(positions, self.si, self.sj, self.rest_lengths, self.K1, self.K2,
                                 self.kM, self.branch_forces(), clamp, a, g, u)
        blocks = a[:, None, None] * u[:, :, None] * u[:, None, :] + g[:, None, None] * np.eye(3)[None]
        ii = 3 * self.si[:, None] + np.arange(3)[None]
        jj = 3 * self.sj[:, None] + np.arange(3)[None]
        rows, cols, vals = [], [], []
        for (r, c, sign) in ((ii, ii, 1.0), (jj, jj, 1.0), (ii, jj, -1.0), (jj, ii, -1.0)):
            rows.append(np.repeat(r, 3, axis=1).ravel())
            cols.append(np.tile(c, (1, 3)).ravel())
            vals.append(sign * blocks.ravel())
        if len(self._vtets):   # volume term, Gauss-Newton part kv/V0 g g^T
            nt = len(self._vtets)
            vg, vc = np.empty((nt, 4, 3)), np.empty(nt)
            kern.volume_tangents(np.ascontiguousarray(positions), self._vtets, self.volume_rest, self.volume_kv, vg, vc)
            g = vg.reshape(nt, 12)
            dof = (3 * self._vtets[:, :, None] + np.arange(3)[None, None]).reshape(nt, 12)
            rows.append(np.repeat(dof, 12, axis=1).ravel())
            cols.append(np.tile(dof, (1, 12)).ravel())
            vals.append((vc[:, None, None] * g[:, :, None] * g[:, None, :]).ravel())
        n3 = 3 * self.n_nodes
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n3, n3))

    # ---------------------------------------------------------------------------------------
    # Quasi-static equilibrium
    def static_solve(self, forces: np.ndarray | None = None, *, tol: float = 1e-8, max_iter: int = 40) -> np.ndarray:
        """Relaxed (long-term) equilibrium under ``forces`` (N,3) N plus gravity, fixed nodes held
        at ``fixed_targets``. Returns a copy of the equilibrium positions (m).

        Load stepping from the rest state (so the result does not depend on the current state
        and stays on the branch connected to it): the fixed nodes move from their rest positions
        to their targets, and the loads grow from 0, the first increment at most a quarter of the
        shortest spring; each increment is solved by Newton's method with the full tangent (plus
        a diagonal shift while it gives no descent direction) and a backtracking Armijo line
        search on the potential energy (on the residual norm where the predicted decrease is below
        the energy's rounding level), then checked for stability: at a saddle (negative lowest
        tangent eigenvalue) it moves to the lowest energy along that mode and re-converges, so the
        result is an energy minimum. Increment control: a converged increment sets the next one
        to ds x clip(sqrt(STATIC_TARGET_ITERATIONS / Newton iterations), 0.5, 2); one that does
        not converge in ``max_iter`` iterations, or that turns more tets inside out, is halved.
        (One jump to an 18 % plate compression of a cube lands on a folded equilibrium with the
        whole top tet layer inverted.) Converged means |residual force on free nodes| <= ``tol``
        * max(|load|, |internal forces|) (docs/numerics.md).
        The Maxwell branches are taken as fully relaxed (zero force); the state is left at the
        solution with zero velocity. ``static_increments`` / ``static_iterations`` record the
        work, ``static_lowest_eigenvalue`` (N/m) the stability check of the last increment.
        Raises :class:`StaticSolveError` if the increment falls below STATIC_MIN_INCREMENT
        (1/4096) of the load.
        """
        if not self.fixed.any():
            raise ConfigError("mass_spring.static_solve needs fixed nodes (set fixed=... or call set_fixed) "
                              "to remove rigid-body motion")
        n = self.n_nodes
        F = np.zeros((n, 3)) if forces is None else np.asarray(forces, dtype=np.float64)
        if F.shape != (n, 3) or not np.all(np.isfinite(F)):
            raise ConfigError(f"forces must be a finite ({n}, 3) array in N, got shape {F.shape}")
        validate.real(tol, "mass_spring.static_solve: tol", lo=0.0, hi=1.0, lo_open=True, hi_open=True,
                      fix="it is the relative residual")
        validate.integer(max_iter, "mass_spring.static_solve: max_iter", lo=1, fix="give a positive integer")
        F = F + self.masses[:, None] * self.gravity[None]
        fixed = self.fixed
        start = np.ascontiguousarray(self.rest_positions.copy())
        goal = self.fixed_targets[fixed]
        travel = float(np.max(np.linalg.norm(goal - start[fixed], axis=1), initial=0.0))
        max_move = 0.25 * float(self.rest_lengths.min())
        ds = 1.0 if travel <= max_move else max_move / travel
        x, s = start, 0.0
        inverted = _count_inverted(x, self.volume.tets)
        self.static_increments = self.static_iterations = 0
        self.static_lowest_eigenvalue = float("nan")
        while s < 1.0:
            s_try = min(1.0, s + ds)
            trial = x.copy()
            trial[fixed] = start[fixed] + s_try * (goal - start[fixed])
            ok, sol, iters = self._newton(trial, s_try * F, tol, max_iter)
            newton_iters = iters
            if ok:
                ok, sol, extra, self.static_lowest_eigenvalue = self._escape_saddle(sol, s_try * F, tol, max_iter)
                iters += extra
            self.static_iterations += iters
            inv = _count_inverted(sol, self.volume.tets) if ok else inverted
            if ok and (inv <= inverted or ds < 1.0 / 256):
                x, s, inverted = sol, s_try, inv
                self.static_increments += 1
                # increment control: aim at STATIC_TARGET_ITERATIONS Newton iterations per increment
                ds = min(1.0, ds * min(2.0, max(0.5, math.sqrt(STATIC_TARGET_ITERATIONS / max(newton_iters, 1)))))
                continue
            ds *= 0.5
            if ds < STATIC_MIN_INCREMENT:
                raise StaticSolveError(
                    f"mass_spring.static_solve did not converge: load step {s:.4f} -> {s_try:.4f} failed with the "
                    f"increment bisected to {ds:.2e} of the load (minimum {STATIC_MIN_INCREMENT:.2e}; Newton "
                    f"iterations {iters}, inverted tets {inv}). Reduce the prescribed displacement/load, or raise "
                    "max_iter/tol")
        x[fixed] = goal
        self.positions = np.ascontiguousarray(x)
        self.velocities = np.zeros_like(self.positions)
        d = self.positions[self.sj] - self.positions[self.si]
        self._dl[:] = np.linalg.norm(d, axis=1) - self.rest_lengths
        self._s[:] = 0.0
        self._pending_dt = 0.0
        self.notify_changed()
        return self.positions.copy()

    def _relaxed_energy(self, x: np.ndarray, F: np.ndarray) -> float:
        """Potential (J) of the relaxed springs and the volume term minus the work of the loads F at positions x."""
        return self._relaxed_energy_terms(x, F)[0]

    def _relaxed_energy_terms(self, x: np.ndarray, F: np.ndarray) -> tuple[float, float]:
        """(potential J, magnitude J of its terms: the scale its rounding error is relative to)."""
        dl = np.linalg.norm(x[self.sj] - x[self.si], axis=1) - self.rest_lengths
        d2 = dl * dl
        stored = float(np.sum(0.5 * self.K1 * d2 + 0.25 * self.K2 * d2 * d2) + self.volume_energy(x))
        work = float(np.sum(F[~self.fixed] * x[~self.fixed]))
        return stored - work, abs(stored) + float(np.sum(np.abs(F[~self.fixed] * x[~self.fixed])))

    def _newton(self, x: np.ndarray, F: np.ndarray, tol: float, max_iter: int, shift: float = 0.0):
        """Modified Newton for the relaxed equilibrium (an energy minimum) with the fixed nodes as in
        ``x``: direction from (K + shift I) dx = R with the full tangent K; the shift (N/m) grows
        tenfold whenever K + shift I gives no descent direction or the line search fails, and
        shrinks tenfold after every full step. Line search: backtracking (halving) with the Armijo
        condition on the energy, ``E(x + a dx) <= E(x) - ARMIJO a dx.R``; where the predicted
        decrease ``a dx.R`` is below the energy's rounding level (ENERGY_NOISE_ULPS ulps of its
        terms: near convergence the energy cannot resolve the step, and whether a rounding-level
        change passes would depend on the CPU's summation order) the condition is taken on the
        residual norm instead, ``|R(x + a dx)| <= (1 - ARMIJO a) |R(x)|``. Converged when
        |R| <= tol x max(|F|, |internal forces|). Returns (converged, positions, iterations)."""
        import scipy.sparse as sp
        import scipy.sparse.linalg as spla

        free = np.repeat(~self.fixed, 3)
        ne = self.n_springs
        zeros_e = np.zeros(ne)
        buf = np.empty_like(x)
        eye = sp.identity(int(free.sum()), format="csc")
        k_scale = float(self.K1.mean()) + 1e-300
        eps = np.finfo(float).eps

        def residual(pos):
            kern.spring_forces(pos, self.si, self.sj, self.rest_lengths, self.K1, self.K2, zeros_e, zeros_e,
                               zeros_e.copy(), zeros_e.copy(), False, buf)
            kern.volume_forces(pos, self._vtets, self.volume_rest, self.volume_kv, buf)
            scale = max(float(np.linalg.norm(F.ravel()[free])), float(np.linalg.norm(buf)), 1e-12)
            return (buf + F).ravel()[free], scale

        x = np.ascontiguousarray(x)
        R, scale = residual(x)
        energy, e_mag = self._relaxed_energy_terms(x, F)
        it = 0
        while it < max_iter:
            rnorm = float(np.linalg.norm(R))
            if not math.isfinite(rnorm):
                return False, x, it
            if rnorm <= tol * scale:
                return True, x, it
            it += 1
            K = self._tangent(x, True, False)[free][:, free].tocsc()
            accepted = None
            while shift < 1e3 * k_scale:
                try:
                    cand = spla.splu((K + shift * eye) if shift > 0 else K).solve(R)
                except RuntimeError:  # exactly singular factor
                    cand = None
                if cand is not None and np.all(np.isfinite(cand)) and float(cand @ R) > 0.0:
                    decrease = float(cand @ R)        # -(directional derivative of the energy) > 0
                    noise = ENERGY_NOISE_ULPS * eps * e_mag
                    step = 1.0
                    for _ in range(30):
                        trial = x.copy()
                        trial.reshape(-1)[free] += step * cand
                        e_t, mag_t = self._relaxed_energy_terms(trial, F)
                        if step * decrease > noise:
                            good = e_t <= energy - ARMIJO * step * decrease
                        else:
                            r_t = residual(trial)
                            good = math.isfinite(e_t) and float(np.linalg.norm(r_t[0])) <= (1.0 - ARMIJO * step) * rnorm
                        if good:
                            accepted = (trial, e_t, mag_t, step)
                            break
                        step *= 0.5
                if accepted is not None:
                    break
                shift = max(10.0 * shift, 1e-3 * k_scale)
            if accepted is None:
                return False, x, it
            x, energy, e_mag, step = accepted
            shift = 0.1 * shift if (step == 1.0 and shift > 1e-6 * k_scale) else (0.0 if step == 1.0 else shift)
            R, scale = residual(x)
        rnorm = float(np.linalg.norm(R))
        return rnorm <= tol * scale, x, max_iter

    def _lowest_mode(self, x: np.ndarray):
        """(eigenvalue N/m, (N,3) mode) of the relaxed tangent on the free nodes at ``x``."""
        import scipy.sparse.linalg as spla

        free = np.repeat(~self.fixed, 3)
        K = self._tangent(x, True, False)[free][:, free].tocsc()
        shift = -1e-3 * float(self.K1.mean())
        try:
            v0 = np.cos(np.arange(K.shape[0]) * 0.7071)   # fixed start vector: deterministic result
            w, v = spla.eigsh(K, k=1, sigma=shift, which="LM", tol=1e-6, v0=v0)
        except (spla.ArpackNoConvergence, RuntimeError):
            return 0.0, None
        mode = np.zeros(x.size)
        mode[free] = v[:, 0]
        return float(w[0]), mode.reshape(-1, 3)

    def _escape_saddle(self, x: np.ndarray, F: np.ndarray, tol: float, max_iter: int):
        """From an equilibrium x, follow negative-curvature modes downhill to a stable equilibrium:
        the lowest-energy point along the mode (both signs, geometric steps) starts a shifted Newton
        solve. Returns (converged, positions, iterations, lowest eigenvalue)."""
        iters = 0
        lam, mode = self._lowest_mode(x)
        for _ in range(6):
            if mode is None or lam >= -1e-9 * float(self.K1.mean()):
                return True, x, iters, lam
            # lowest energy along +-mode over steps of a quarter of the shortest spring / 2^k: the
            # first Newton iterate starts well down the slope instead of at the saddle's rim
            t_max = 0.25 * float(self.rest_lengths.min()) / float(np.max(np.linalg.norm(mode, axis=1)))
            e0, best = self._relaxed_energy(x, F), None
            for sign in (1.0, -1.0):
                for k in range(16):
                    trial = x + sign * t_max * 0.5 ** k * mode
                    e_t = self._relaxed_energy(trial, F)
                    if e_t < e0 and (best is None or e_t < best[0]):
                        best = (e_t, trial)
            if best is None:
                return True, x, iters, lam
            ok, x, n_it = self._newton(best[1], F, tol, max_iter, shift=2.0 * abs(lam))
            iters += n_it
            if not ok:
                return False, x, iters, lam
            lam, mode = self._lowest_mode(x)
        return lam >= -1e-9 * float(self.K1.mean()), x, iters, lam

    def describe(self) -> dict[str, Any]:
        out = super().describe()
        out.update({"springs": self.n_springs, "K1_mean_N_per_m": float(self.K1.mean()),
                    "K2_mean_N_per_m3": float(self.K2.mean()), "b0_mean_Ns_per_m": float(self.b0.mean()),
                    "b1_mean_Ns_per_m": float(self.b1.mean()), "volume_stiffness": self.volume_stiffness,
                    "volume_kv_mean_Pa": float(self.volume_kv.mean()) if len(self.volume_kv) else 0.0})
        return out
