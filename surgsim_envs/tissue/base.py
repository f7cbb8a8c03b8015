"""The tissue plugin interface every deformation model implements.

A :class:`TissueModel` owns the state of one deformable body (positions, velocities, internal
state such as viscoelastic branches or strain history) and advances it with :meth:`step`.
It knows nothing of MuJoCo: the scene feeds it external nodal forces (contact) and reads back
positions. Units: m, s, kg, N, J.

Subclasses implement :meth:`_advance` (and :meth:`critical_dt`, :meth:`elastic_energy`,
:meth:`internal_forces`); the base class does validation, bookkeeping, Dirichlet nodes and the
stability guard, so every model fails the same way (:class:`TissueUnstableError`).
"""

from __future__ import annotations

import abc
import math
from typing import Any, ClassVar, Mapping

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.volume import Volume
from surgsim_envs.tissue.guard import StabilityGuard
from surgsim_envs.tissue.materials import Material, get_material

ELEMENT_FIELDS = ("young", "poisson", "density", "damping", "relax_fraction", "relax_time", "nonlinear")
#: integrator="auto" runs the explicit integrator while dt <= AUTO_SAFETY x critical_dt(), else the implicit one
AUTO_SAFETY = 0.8
#: integrator="auto" re-evaluates critical_dt() when dt changes and every AUTO_RECHECK_STEPS steps
AUTO_RECHECK_STEPS = 100


class TissueModel(abc.ABC):
    """Base class of all tissue models.

    Parameters
    ----------
    volume: the mesh (nodes in m). Surface-only models use ``volume.surface`` only.
    material: bulk material (a :class:`Material`, a preset name or a dict of fields).
    region_materials: optional {label: material} for tets with that region label (inclusions,
        layers); heterogeneity is then just per-element fields.
    fixed: optional indices or boolean mask of Dirichlet nodes (held at their rest positions
        until moved with :meth:`set_fixed`).
    gravity: (3,) m/s^2 body acceleration, default zero (tissue usually rests on its bed).

    Attributes a scene may read every step: ``positions`` (N,3), ``velocities`` (N,3),
    ``masses`` (N,), ``surface`` (F,3), ``surface_nodes`` (S,), ``fixed`` (N,) bool,
    ``time`` (s), ``fields`` {name: per-element (T,) or per-node (N,) array}.
    """

    #: registry name, set by subclasses
    name: ClassVar[str] = "base"
    #: one-line description for ``surgsim models``
    summary: ClassVar[str] = ""
    #: concrete integrators this model supports; the first is the default unless ``default_integrator`` is set
    integrators: ClassVar[tuple[str, ...]] = ("symplectic",)
    #: (explicit, implicit) pair that ``integrator="auto"`` chooses between; None: no "auto"
    auto_pair: ClassVar[tuple[str, str] | None] = None
    #: integrator used when none is given (None: ``integrators[0]``; may be "auto" if ``auto_pair`` is set)
    default_integrator: ClassVar[str | None] = None
    #: True for models that only use the surface mesh (e.g. paper 000)
    surface_only: ClassVar[bool] = False
    #: True for models solved quasi-statically (no inertia; velocities are finite differences)
    quasi_static: ClassVar[bool] = False

    def __init__(self, volume: Volume, material: Material | str | Mapping[str, Any] = "liver", *,
                 region_materials: Mapping[int, Any] | None = None, fixed=None,
                 integrator: str | None = None, gravity=(0.0, 0.0, 0.0), guard: StabilityGuard | None = None):
        if not isinstance(volume, Volume):
            raise ConfigError(f"volume must be a surgsim_envs.geometry.Volume, got {type(volume).__name__}; "
                              "build one with surgsim_envs.geometry.make_volume(...) or box_volume(...)")
        if not self.surface_only:
            volume.check()
        self.volume = volume
        self.material = get_material(material)
        self.region_materials = {int(k): get_material(v) for k, v in (region_materials or {}).items()}
        labels = volume.node_labels if self.surface_only else volume.labels   # surface-only: per-node labels
        unknown = set(self.region_materials) - set(np.unique(labels).tolist())
        if unknown:
            raise ConfigError(f"region_materials labels {sorted(unknown)} do not occur in volume '{volume.name}' "
                              f"(labels present: {sorted(np.unique(volume.labels).tolist())})")
        self.integrator = integrator or self.default_integrator or self.integrators[0]
        if self.integrator == "auto" and self.auto_pair is None:
            raise ConfigError(f"model '{self.name}' has no integrator 'auto' (it needs both an explicit and an "
                              f"implicit integrator); choose one of {list(self.integrators)}")
        if self.integrator != "auto" and self.integrator not in self.integrators:
            raise ConfigError(f"model '{self.name}' has no integrator {self.integrator!r}; "
                              f"choose one of {self.integrator_names()}")
        # integrator="auto": the concrete integrator of the current step and the cached decision inputs
        self._active: str | None = None if self.integrator == "auto" else self.integrator
        self._auto_dt = float("nan")      # dt of the last critical_dt() evaluation (s)
        self._auto_step = 0               # step count at that evaluation
        self._auto_crit = float("nan")    # critical_dt() at that evaluation (s)
        self.gravity = np.asarray(gravity, dtype=np.float64).reshape(3)

        self.rest_positions = volume.nodes.copy()
        self.surface = volume.surface
        self.surface_nodes = volume.surface_nodes
        n = len(self.rest_positions)
        self.fields = self._build_fields()
        self.masses = self._lumped_masses()
        # surface-only models carry mass on surface nodes only (interior nodes of a tet volume stay still)
        weighed = self.surface_nodes if self.surface_only else np.arange(n)
        if np.any(self.masses[weighed] <= 0):
            bad = int(weighed[np.flatnonzero(self.masses[weighed] <= 0)[0]])
            raise ConfigError(f"model '{self.name}': node {bad} has mass {self.masses[bad]:.3g} kg (isolated node?); "
                              "remove unused nodes from the volume")
        self.fixed = np.zeros(n, dtype=bool)
        self.fixed_targets = self.rest_positions.copy()
        self._fixed_idx = np.zeros(0, dtype=np.int64)
        if fixed is not None:
            self.set_fixed(fixed)
        self.guard = guard or StabilityGuard()
        self.positions = self.rest_positions.copy()
        self.velocities = np.zeros_like(self.positions)
        self.external_forces = np.zeros_like(self.positions)
        self.time = 0.0
        self.steps = 0
        self._last_dt = float("nan")

    # ---------------------------------------------------------------------------------------
    # Material fields and mass
    def _build_fields(self) -> dict[str, np.ndarray]:
        labels = self.volume.labels if not self.surface_only else self.volume.node_labels
        out = {}
        for key in ELEMENT_FIELDS:
            arr = np.full(len(labels), float(getattr(self.material, key)))
            for label, mat in self.region_materials.items():
                arr[labels == label] = float(getattr(mat, key))
            out[key] = arr
        return out

    def _lumped_masses(self) -> np.ndarray:
        """Row-sum lumped mass (kg): each tet gives rho V / 4 to its nodes."""
        n = self.volume.n_nodes
        if self.surface_only or len(self.volume.tets) == 0:
            raise NotImplementedError("surface-only models must override _lumped_masses")
        vol = self.volume.tet_volumes()
        m = np.zeros(n)
        np.add.at(m, self.volume.tets.reshape(-1), np.repeat(self.fields["density"] * vol / 4.0, 4))
        return m

    @property
    def n_nodes(self) -> int:
        return len(self.positions)

    @property
    def total_mass(self) -> float:
        return float(self.masses.sum())

    # ---------------------------------------------------------------------------------------
    # Dirichlet nodes
    def set_fixed(self, nodes, targets=None) -> None:
        """Fix ``nodes`` (indices or bool mask) at ``targets`` (K,3) m, or at their rest positions.

        Calling again with the same nodes and new targets moves them (prescribed displacement).
        """
        idx = self._as_indices(nodes, "fixed nodes")
        if targets is None:
            targets = self.rest_positions[idx]
        targets = np.asarray(targets, dtype=np.float64).reshape(-1, 3)
        if len(targets) not in (1, len(idx)):
            raise ConfigError(f"targets must have shape ({len(idx)}, 3) or (3,), got {np.shape(targets)}")
        if not np.all(np.isfinite(targets)):
            raise ConfigError("fixed-node targets contain NaN/inf")
        self.fixed[idx] = True
        self.fixed_targets[idx] = targets
        if hasattr(self, "positions"):
            self.positions[idx] = self.fixed_targets[idx]
            self.velocities[idx] = 0.0
        self._fixed_idx = np.flatnonzero(self.fixed)
        self._on_fixed_changed()

    def release(self, nodes=None) -> None:
        """Free ``nodes`` (all if None) from their Dirichlet condition."""
        if nodes is None:
            self.fixed[:] = False
        else:
            self.fixed[self._as_indices(nodes, "released nodes")] = False
        self._fixed_idx = np.flatnonzero(self.fixed)
        self._on_fixed_changed()

    def _on_fixed_changed(self) -> None:
        """Hook for models that cache factorisations depending on the fixed set."""

    def _as_indices(self, nodes, what: str) -> np.ndarray:
        arr = np.asarray(nodes)
        n = len(self.rest_positions)
        if arr.dtype == bool:
            if arr.shape != (n,):
                raise ConfigError(f"{what}: boolean mask must have shape ({n},), got {arr.shape}")
            return np.flatnonzero(arr)
        arr = arr.astype(np.int64).reshape(-1)
        if len(arr) and (arr.min() < 0 or arr.max() >= n):
            raise ConfigError(f"{what}: indices must lie in [0, {n}), got [{arr.min()}, {arr.max()}]")
        return arr

    # ---------------------------------------------------------------------------------------
    # Stepping
    def step(self, dt: float, forces: np.ndarray | None = None, stiffness: np.ndarray | None = None) -> None:
        """Advance by ``dt`` seconds under external nodal ``forces`` (N,3) in N.

        ``stiffness`` (optional, (N,) N/m) is the isotropic stiffness of the external forces
        (-dF/dx per node, e.g. contact penalty springs); implicit integrators treat it implicitly.
        Raises :class:`TissueUnstableError` if the state diverges.
        """
        if not (isinstance(dt, (float, int, np.floating)) and math.isfinite(dt) and dt > 0):
            raise ConfigError(f"dt must be a positive number of seconds, got {dt!r}; default is 1e-3")
        if forces is None:
            forces = self.external_forces
        elif forces.shape != self.positions.shape:
            raise ConfigError(f"forces must have shape {self.positions.shape}, got {forces.shape}")
        self._last_dt = float(dt)
        if self.integrator == "auto":
            self._active = self._auto_choice(float(dt), stiffness)
        self._advance(float(dt), forces, stiffness)
        fx = self._fixed_idx
        if fx.size:
            self.positions[fx] = self.fixed_targets[fx]
            self.velocities[fx] = 0.0
        self.time += dt
        self.steps += 1
        self.guard.check(self, dt)

    @abc.abstractmethod
    def _advance(self, dt: float, forces: np.ndarray, stiffness: np.ndarray | None) -> None:
        """Update ``positions``/``velocities`` (and internal state) in place, with
        :attr:`active_integrator` (never "auto")."""

    # ---------------------------------------------------------------------------------------
    # Integrator choice ("auto")
    @classmethod
    def integrator_names(cls) -> list[str]:
        """Names accepted by ``integrator=``: the concrete ones, plus "auto" if the model has a pair."""
        return list(cls.integrators) + (["auto"] if cls.auto_pair is not None else [])

    @property
    def active_integrator(self) -> str:
        """The concrete integrator in use: ``integrator`` itself, or for "auto" the one chosen at the
        last step (before the first step: the choice for dt = 1 ms at the current state)."""
        if self._active is None:
            return self.choose_integrator(1e-3)
        return self._active

    def choose_integrator(self, dt: float, stiffness: np.ndarray | None = None) -> str:
        """The integrator "auto" picks (or would pick, for models built with an explicit name) for a
        step of ``dt`` s at the current state: the explicit one
        if ``dt <= AUTO_SAFETY * critical_dt()`` (contact ``stiffness`` (N,) N/m, if given, lowers
        the critical dt: omega^2 += max(k_c / m)), else the implicit one. Pure function of the state."""
        if self.auto_pair is None:
            return self.active_integrator
        return self._pick(dt, float(self.critical_dt()), self._contact_rate(stiffness))

    def _contact_rate(self, stiffness) -> float:
        """max over nodes of k_c / m (1/s^2) of the contact stiffness; 0 if none or malformed
        (the model validates it)."""
        if stiffness is None:
            return 0.0
        kc = np.asarray(stiffness, dtype=np.float64)
        if kc.shape != self.masses.shape or not kc.any():
            return 0.0
        rate = float(np.max(kc / self.masses))
        return rate if math.isfinite(rate) and rate > 0 else 0.0

    def _pick(self, dt: float, crit: float, contact_rate: float) -> str:
        explicit, implicit = self.auto_pair
        if not (crit > 0):                        # NaN or zero: no explicit limit known
            return implicit
        if contact_rate > 0 and math.isfinite(crit):
            omega = 2.0 / crit                    # the model's limit as an undamped frequency (1/s)
            crit = 2.0 / math.sqrt(omega * omega + contact_rate)
        return explicit if dt <= AUTO_SAFETY * crit else implicit

    def _auto_choice(self, dt: float, stiffness) -> str:
        """Integrator for this step under "auto": critical_dt() is re-evaluated when dt changes,
        every AUTO_RECHECK_STEPS steps and after reset(); the contact stiffness is applied every step."""
        if dt != self._auto_dt or self.steps - self._auto_step >= AUTO_RECHECK_STEPS or not (self._auto_crit > 0):
            self._auto_crit = float(self.critical_dt())
            self._auto_dt, self._auto_step = dt, self.steps
        return self._pick(dt, self._auto_crit, self._contact_rate(stiffness))

    def static_solve(self, forces: np.ndarray | None = None, **kwargs) -> np.ndarray:
        """Equilibrium positions under ``forces`` with the current Dirichlet nodes (if supported)."""
        raise NotImplementedError(f"model '{self.name}' has no static solver")

    # ---------------------------------------------------------------------------------------
    # Energies and forces
    def kinetic_energy(self) -> float:
        """0.5 sum m v^2 (J)."""
        return 0.5 * float(np.einsum("i,ij,ij->", self.masses, self.velocities, self.velocities))

    @abc.abstractmethod
    def elastic_energy(self) -> float:
        """Stored elastic energy (J) of the current configuration."""

    @abc.abstractmethod
    def internal_forces(self) -> np.ndarray:
        """(N,3) internal (elastic + viscous) nodal forces in N at the current state.

        At a fixed node, ``-internal_forces()`` is the reaction the support supplies.
        """

    def reaction_forces(self) -> np.ndarray:
        """(K,3) forces (N) the supports exert ON the tissue at its fixed nodes (fixed-node order).

        The tissue pushes on its supports with the opposite force; at equilibrium this balances the
        internal forces, so it is ``-internal_forces()[fixed]``."""
        return -self.internal_forces()[self.fixed]

    def momentum(self) -> np.ndarray:
        """Linear momentum sum m v (kg m/s)."""
        return self.masses @ self.velocities

    @abc.abstractmethod
    def critical_dt(self) -> float:
        """Estimated largest stable dt (s) for the explicit integrator (inf if unconditionally stable)."""

    def inverted_elements(self) -> int:
        """Number of inverted elements (0 for models without elements)."""
        return 0

    # ---------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Back to rest: positions, velocities, internal state, time. Dirichlet set kept."""
        self.positions = self.rest_positions.copy()
        fx = self.fixed
        self.positions[fx] = self.fixed_targets[fx]
        self.velocities = np.zeros_like(self.positions)
        self.external_forces = np.zeros_like(self.positions)
        self.time = 0.0
        self.steps = 0
        self.guard.reset()
        if self.integrator == "auto":
            self._active, self._auto_dt, self._auto_step, self._auto_crit = None, float("nan"), 0, float("nan")
        self._reset_state()

    def _reset_state(self) -> None:
        """Hook: clear model-specific internal state (viscoelastic branches, history...)."""

    def describe(self) -> dict[str, Any]:
        """Summary for reports."""
        return {"model": self.name, "integrator": self.integrator, "active_integrator": self.active_integrator,
                "nodes": self.n_nodes,
                "elements": int(len(self.volume.tets)), "mass_kg": self.total_mass,
                "material": self.material.name, "critical_dt": self.critical_dt()}

    def __repr__(self) -> str:
        integ = self.integrator if self._active is None or self._active == self.integrator else \
            f"{self.integrator} ({self._active})"
        return f"<{type(self).__name__} '{self.name}' {self.n_nodes} nodes, integrator={integ}>"
