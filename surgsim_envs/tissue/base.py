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
from numba import njit

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.volume import Volume
from surgsim_envs.tissue.capabilities import CAPABILITIES, CapabilityError, check_names
from surgsim_envs.tissue.capabilities import require as _require
from surgsim_envs.tissue.guard import StabilityGuard, first_non_finite
from surgsim_envs.materials import Material, get_material

ELEMENT_FIELDS = ("young", "poisson", "density", "damping", "relax_fraction", "relax_time", "nonlinear")
#: THE safety factor on the explicit stability limit (the only one anywhere): ``stable_dt() =
#: DT_SAFETY * critical_dt()``; integrator="auto" runs the explicit integrator while dt <= stable_dt()
#: (contact stiffness included), else the implicit one; scenes, benchmarks and guards use stable_dt().
DT_SAFETY = 0.8
#: integrator="auto" re-evaluates critical_dt() when dt changes and every AUTO_RECHECK_STEPS steps
AUTO_RECHECK_STEPS = 100


@njit(cache=True, nogil=True, error_model="numpy")
def max_ratio(kc, masses):
    """``np.max(kc / masses)`` as that expression gives it (NaN if any ratio is NaN, e.g. 0/0 at a
    massless interior node), and 0.0 when every ``kc`` is zero, without the temporary array."""
    best = -np.inf
    nonzero = False
    for i in range(kc.shape[0]):
        if kc[i] != 0.0:
            nonzero = True
        r = kc[i] / masses[i]
        if r != r:
            return np.nan
        if r > best:
            best = r
    return best if nonzero else 0.0


@njit(cache=True, nogil=True)
def hold_fixed_nodes(positions, velocities, targets, nodes):
    """``positions[nodes] = targets[nodes]`` and ``velocities[nodes] = 0`` ((N,3) arrays), in place."""
    for k in range(nodes.shape[0]):
        i = nodes[k]
        for j in range(3):
            positions[i, j] = targets[i, j]
            velocities[i, j] = 0.0


def von_mises(sig: np.ndarray) -> np.ndarray:
    """(T,) von Mises equivalent (Pa) of stresses (T,3,3)."""
    tr = np.trace(sig, axis1=1, axis2=2)
    dev = sig - tr[:, None, None] / 3.0 * np.eye(3)
    return np.sqrt(1.5 * np.einsum("tij,tij->t", dev, dev))


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
    #: what the model can do (tissue/capabilities.py); scenes and tasks query these, never the name
    capabilities: ClassVar[frozenset[str]] = frozenset({"forces"})
    #: a step is an equilibrium under the contact linearised about the positions it starts from, and
    #: the scene may solve it again about the positions it reached while the contact set there differs
    #: (:mod:`surgsim_envs.contact.contact_set`), through :meth:`step_state` / :meth:`restore_step_state`
    resolves_contact_set: ClassVar[bool] = False
    #: material fields :meth:`scale_material` / :meth:`set_field` may change (the model re-derives
    #: whatever depends on them in :meth:`_on_material_changed`)
    material_fields: ClassVar[tuple[str, ...]] = ()
    #: names of the per-node scalar fields :meth:`node_fields` returns
    node_field_names: ClassVar[tuple[str, ...]] = ("displacement", "stress")
    #: constructor options the model needs where a tool presses a concentrated load into it (a probe
    #: tip about one lattice spacing wide): scenes that do so build it with these (tissue contract v2)
    point_load_options: ClassVar[Mapping[str, Any]] = {}
    #: replace ``point_load_options`` where the scene steps the model implicitly: an option chosen only to
    #: keep the explicit step (a capped Poisson ratio) is no constraint there, and the model gets its full
    #: material instead
    implicit_point_load_options: ClassVar[Mapping[str, Any]] = {}
    #: module of the model's compiled step (tissue/compiled.py), for this exact class only (a
    #: subclass that changes the physics does not inherit it); None: Python steps only
    compiled_step_module: ClassVar[str | None] = None

    #: bumped by :meth:`notify_changed` whenever the model replaces an array (reset, a material or
    #: Dirichlet change, new buffers): a compiled caller that holds raw pointers to the model's arrays
    #: repacks them when it moves; writes in place keep it
    state_version: int = 0

    def notify_changed(self) -> None:
        """Tell compiled callers that arrays of the model were replaced (new objects): call after
        assigning a new array to any attribute a compiled step reads. ``positions`` and
        ``velocities`` are also followed by identity, so assigning those needs no call."""
        self.state_version += 1

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        cls.capabilities = frozenset(check_names(cls.capabilities, f"model class {cls.__name__}"))

    @classmethod
    def require(cls, capability: str, task: str = "this task") -> None:
        """Raise :class:`CapabilityError` (a ConfigError naming the model, the capability and
        ``task``) unless this model declares ``capability``."""
        _require(cls, capability, task)

    @classmethod
    def has(cls, capability: str) -> bool:
        """Whether the model declares ``capability`` (ConfigError for an unknown name)."""
        if capability not in CAPABILITIES:
            raise ConfigError(f"unknown capability {capability!r}; valid capabilities: {sorted(CAPABILITIES)}")
        return capability in cls.capabilities

    def __init__(self, volume: Volume, material: Material | str | Mapping[str, Any] = "liver", *,
                 region_materials: Mapping[int, Any] | None = None, fixed=None,
                 integrator: str | None = None, gravity=(0.0, 0.0, 0.0), guard: StabilityGuard | None = None):
        if not isinstance(volume, Volume):
            raise ConfigError(f"volume must be a surgsim_envs.geometry.Volume, got {type(volume).__name__}; "
                              "build one with surgsim_envs.geometry.make_volume(...) or box_volume(...)")
        surface_only = "surface_only" in self.capabilities
        if not surface_only:
            volume.check()
        self.volume = volume
        self.material = get_material(material)
        self.region_materials = {int(k): get_material(v) for k, v in (region_materials or {}).items()}
        labels = volume.node_labels if surface_only else volume.labels   # surface-only: per-node labels
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
        self._fields0 = {k: v.copy() for k, v in self.fields.items()}
        self.masses = self._lumped_masses()
        # surface-only models carry mass on surface nodes only (interior nodes of a tet volume stay still)
        weighed = self.surface_nodes if surface_only else np.arange(n)
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
        if "quasi_static" in self.capabilities and self.guard.max_jump is None:
            # no inertia: released (a grasp that lets go), the body springs back to its new equilibrium
            # within one step, whatever dt; a jump beyond the body's own size is a divergence
            span = self.rest_positions.max(axis=0) - self.rest_positions.min(axis=0)
            self.guard.max_jump = float(np.linalg.norm(span))
        self.positions = self.rest_positions.copy()
        self.velocities = np.zeros_like(self.positions)
        self.external_forces = np.zeros_like(self.positions)
        #: (N,3) N, the external force integrated over the last step (contract v2): the forces given
        #: plus, for an implicit treatment of the contact stiffness, the increment it added
        self.integrated_external_forces = np.zeros_like(self.positions)
        self.time = 0.0
        self.steps = 0
        self._last_dt = float("nan")

    # ---------------------------------------------------------------------------------------
    # Material fields and mass
    def _build_fields(self) -> dict[str, np.ndarray]:
        labels = self.volume.node_labels if "surface_only" in self.capabilities else self.volume.labels
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
        if "surface_only" in self.capabilities or len(self.volume.tets) == 0:
            raise NotImplementedError("surface-only models must override _lumped_masses")
        vol = self.volume.tet_volumes()
        m = np.zeros(n)
        np.add.at(m, self.volume.tets.reshape(-1), np.repeat(self.fields["density"] * vol / 4.0, 4))
        return m

    def element_centroids(self) -> np.ndarray:
        """(T,3) m rest centroids of the elements that carry the material fields (tets; for a
        surface-only model its nodes), to build masks for :meth:`scale_material`."""
        if "surface_only" in self.capabilities:
            return self.rest_positions.copy()
        return self.rest_positions[self.volume.tets].mean(axis=1)

    def element_vertices(self) -> np.ndarray:
        """(T,4,3) m rest corners of the elements that carry the material fields (tets; for a
        surface-only model (N,1,3), its nodes), to weigh a region's share of each element."""
        if "surface_only" in self.capabilities:
            return self.rest_positions[:, None, :].copy()
        return self.rest_positions[self.volume.tets]

    def material_points(self) -> np.ndarray:
        """(T, Q, 3) m rest points at which each element samples its material (its quadrature points):
        one, the centroid, for the elements of constant strain here; a model that integrates its
        elements at several points (``fem_hex``: 8 Gauss points) returns them, so that a region
        (an inclusion) is seen point by point by :meth:`scale_material_at_points`."""
        return self.element_centroids()[:, None, :]

    def scale_material_at_points(self, name: str, factors) -> None:
        """Multiply material field ``name`` by ``factors`` ((T, Q) > 0, one per point of
        :meth:`material_points`) relative to its value at build, everywhere: an element whose points
        differ is integrated with each point's value (a model with one point per element takes
        ``factors[:, 0]``, as :meth:`scale_material` would). E.g. a sphere 30x stiffer::

            inside = np.linalg.norm(model.material_points() - centre, axis=2) < radius
            model.scale_material_at_points("young", np.where(inside, 30.0, 1.0))
        """
        f = self._point_factors(name, factors)
        if f.shape[1] != 1:
            raise NotImplementedError(f"tissue model '{self.name}' samples its material at {f.shape[1]} points per "
                                      "element and must override scale_material_at_points")
        self.scale_material(name, f[:, 0])

    def _point_factors(self, name: str, factors) -> np.ndarray:
        """``factors`` checked against :meth:`material_points`' (T, Q): finite, > 0 (the field's name is
        checked by the method that applies them)."""
        shape = self.material_points().shape[:2]
        f = np.asarray(factors, dtype=np.float64)
        if f.shape != shape:
            raise ConfigError(f"scale_material_at_points: factors must be a {shape} array (one per point of "
                              f"material_points()), got shape {f.shape}")
        if not np.all(np.isfinite(f)) or np.any(f <= 0):
            raise ConfigError("scale_material_at_points: factors must be finite and > 0, got min "
                              f"{float(np.min(f)) if f.size else float('nan'):.3g}")
        return f

    def _check_field_name(self, name: str) -> None:
        if name not in self.fields:
            raise ConfigError(f"unknown material field {name!r}; fields: {sorted(self.fields)}")
        if name not in self.material_fields:
            raise CapabilityError(f"tissue model '{self.name}' cannot change material field {name!r} after build; "
                                  f"it re-derives only {sorted(self.material_fields)}")

    def scale_material(self, name: str = "young", factor=1.0, mask=None) -> None:
        """Multiply material field ``name`` by ``factor`` (a scalar or (T,) array, > 0) relative to
        its value at build, on the elements where ``mask`` ((T,) bool, default all) is True; the
        others keep their current value. The model re-derives what depends on it (springs, element
        stiffness, factorisations). E.g. an inclusion three times stiffer than a slab scaled by 0.9::

            model.scale_material("young", 0.9)
            model.scale_material("young", 2.7, mask=inside)
        """
        self._check_field_name(name)
        t = len(self.fields[name])
        f = np.asarray(factor, dtype=np.float64)
        if f.ndim not in (0, 1) or (f.ndim == 1 and f.shape != (t,)):
            raise ConfigError(f"scale_material: factor must be a number or a ({t},) array, got shape {f.shape}")
        if not np.all(np.isfinite(f)) or np.any(f <= 0):
            raise ConfigError(f"scale_material: factor must be finite and > 0, got min {float(np.min(f)):.3g}")
        values = self.fields[name].copy()
        new = self._fields0[name] * np.broadcast_to(f, (t,))
        if mask is None:
            values[:] = new
        else:
            m = np.asarray(mask)
            if m.dtype != bool or m.shape != (t,):
                raise ConfigError(f"scale_material: mask must be a ({t},) bool array (one per element, see "
                                  f"element_centroids()), got dtype {m.dtype} shape {m.shape}")
            values[m] = new[m]
        self._apply_field(name, values)

    def set_field(self, name: str, values) -> None:
        """Set material field ``name`` to absolute ``values`` (a number or (T,) array, SI units)."""
        self._check_field_name(name)
        t = len(self.fields[name])
        v = np.asarray(values, dtype=np.float64)
        if v.ndim not in (0, 1) or (v.ndim == 1 and v.shape != (t,)) or not np.all(np.isfinite(v)):
            raise ConfigError(f"set_field({name!r}): values must be a finite number or ({t},) array, got shape {v.shape}")
        self._apply_field(name, np.broadcast_to(v, (t,)).copy())

    def _apply_field(self, name: str, values: np.ndarray) -> None:
        old = self.fields[name]
        self.fields[name] = values
        try:
            if name == "density":
                if np.any(values <= 0):
                    raise ConfigError("density must be > 0 kg/m^3 in every element")
                self.masses = self._lumped_masses()
            self._on_material_changed(name)
        except Exception:
            self.fields[name] = old
            if name == "density":
                self.masses = self._lumped_masses()
            self._on_material_changed(name)
            raise
        finally:
            self.notify_changed()
        if self.integrator == "auto":
            self._auto_crit = float("nan")   # re-evaluate critical_dt() at the next step

    def _on_material_changed(self, name: str) -> None:
        """Hook: re-derive everything that depends on material field ``name`` (masses are done)."""

    # ---------------------------------------------------------------------------------------
    # Scalar fields for display
    @classmethod
    def field_names(cls) -> list[str]:
        """Names of the per-node scalar fields (``node_fields()`` keys)."""
        return list(cls.node_field_names)

    def node_fields(self, names=None) -> dict[str, np.ndarray]:
        """{name: (N,) array} per-node scalar fields for display: ``"displacement"`` (m, |x - X|),
        ``"stress"`` (Pa, a von Mises measure), plus the model's own; ``names`` selects some."""
        names = self.field_names() if names is None else [names] if isinstance(names, str) else list(names)
        out = {}
        for n in names:
            out[n] = self.node_field(n)
        return out

    def node_field(self, name: str) -> np.ndarray:
        """One per-node scalar field (see :meth:`node_fields`); ConfigError listing the names if unknown."""
        if name not in self.node_field_names:
            raise ConfigError(f"model '{self.name}' has no node field {name!r}; fields: {self.field_names()}")
        if name == "displacement":
            return np.linalg.norm(self.positions - self.rest_positions, axis=1)
        if name == "stress":
            return self.node_stress()
        return np.asarray(self._node_field(name), dtype=np.float64)

    def _node_field(self, name: str) -> np.ndarray:
        """Hook for model-specific node fields beyond displacement and stress."""
        raise ConfigError(f"model '{self.name}' lists node field {name!r} but does not compute it")

    def node_stress(self) -> np.ndarray:
        """(N,) Pa von Mises stress per node: the volume-weighted mean over the node's elements of
        ``element_stress()`` (models without elements override this)."""
        sig = self.element_stress()
        vm = von_mises(sig)
        tets = self.volume.tets
        w = np.abs(self.volume.tet_volumes())
        num = np.zeros(self.n_nodes)
        den = np.zeros(self.n_nodes)
        np.add.at(num, tets.ravel(), np.repeat(vm * w, 4))
        np.add.at(den, tets.ravel(), np.repeat(w, 4))
        return num / np.where(den > 0, den, 1.0)

    def element_stress(self) -> np.ndarray:
        """(T,3,3) Cauchy stress (Pa) per element (models with elements implement it)."""
        raise NotImplementedError(f"model '{self.name}' implements neither element_stress() nor node_stress()")

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
        self.notify_changed()

    def release(self, nodes=None) -> None:
        """Free ``nodes`` (all if None) from their Dirichlet condition."""
        if nodes is None:
            self.fixed[:] = False
        else:
            self.fixed[self._as_indices(nodes, "released nodes")] = False
        self._fixed_idx = np.flatnonzero(self.fixed)
        self._on_fixed_changed()
        self.notify_changed()

    @property
    def fixed_nodes(self) -> np.ndarray:
        """(K,) int64 indices of the Dirichlet nodes (replaced, not written, when the set changes)."""
        return self._fixed_idx

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
        if not (isinstance(dt, (float, int, np.floating)) and math.isfinite(dt) and dt > 0):   # once per step:
            validate.positive(dt, "dt", unit="s", fix="the default is 1e-3 s")              # the check inline
        if forces is None:
            forces = self.external_forces
        elif forces.shape != self.positions.shape:
            raise ConfigError(f"forces must have shape {self.positions.shape}, got {forces.shape}")
        self.guard.check_inputs(self, forces, stiffness)  # NaN/inf input: refused before it reaches the state
        self._step_body(float(dt), forces, stiffness)

    def step_prevalidated(self, dt: float, forces: np.ndarray, stiffness: np.ndarray | None) -> None:
        """:meth:`step` for a caller that owns and has checked its arguments once (the scene's
        physics loop): ``dt`` a positive float (s), ``forces`` a C-contiguous float64 (N,3) array
        (N), ``stiffness`` None or a C-contiguous float64 (N,) array (N/m). Skips only those
        type/shape checks: NaN/inf input is still refused with the same error before the state is
        touched, and the stability guard runs as in :meth:`step`. Physics identical to :meth:`step`."""
        if first_non_finite(forces) >= 0 or (isinstance(stiffness, np.ndarray) and first_non_finite(stiffness) >= 0):
            self.guard.check_inputs(self, forces, stiffness)   # raises NonFiniteInputError naming the node
        self._step_body(dt, forces, stiffness)

    def _step_body(self, dt: float, forces: np.ndarray, stiffness: np.ndarray | None) -> None:
        self._last_dt = dt
        np.copyto(self.integrated_external_forces, forces)
        if self.integrator == "auto":
            self._active = self._auto_choice(dt, stiffness)
        self._advance(dt, forces, stiffness)
        fx = self._fixed_idx
        if fx.size:
            hold_fixed_nodes(self.positions, self.velocities, self.fixed_targets, fx)
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
        if ``dt <= stable_dt() = DT_SAFETY * critical_dt()`` (contact ``stiffness`` (N,) N/m, if given, lowers
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
        if kc.shape != self.masses.shape:
            return 0.0
        rate = max_ratio(kc, self.masses)
        return rate if math.isfinite(rate) and rate > 0 else 0.0

    def _pick(self, dt: float, crit: float, contact_rate: float) -> str:
        explicit, implicit = self.auto_pair
        if not (crit > 0):                        # NaN or zero: no explicit limit known
            return implicit
        if contact_rate > 0 and math.isfinite(crit):
            omega = 2.0 / crit                    # the model's limit as an undamped frequency (1/s)
            crit = 2.0 / math.sqrt(omega * omega + contact_rate)
        return explicit if dt <= DT_SAFETY * crit else implicit

    def _auto_choice(self, dt: float, stiffness) -> str:
        """Integrator for this step under "auto": critical_dt() is re-evaluated when dt changes,
        every AUTO_RECHECK_STEPS steps and after reset(); the contact stiffness is applied every step."""
        if dt != self._auto_dt or self.steps - self._auto_step >= AUTO_RECHECK_STEPS or not (self._auto_crit > 0):
            self.refresh_critical_dt(dt)
        return self._pick(dt, self._auto_crit, self._contact_rate(stiffness))

    def auto_decision(self) -> tuple[float, float, int]:
        """(critical dt s, the dt it was evaluated for, the step count then) that integrator "auto"
        decides with (NaN, NaN, 0 before the first evaluation)."""
        return self._auto_crit, self._auto_dt, self._auto_step

    def refresh_critical_dt(self, dt: float) -> tuple[float, float, int]:
        """Re-evaluate ``critical_dt()`` for "auto" at the current state and step ``dt``, as a step
        does when it is due (dt changed, every AUTO_RECHECK_STEPS steps, after reset()); returns
        :meth:`auto_decision`."""
        self._auto_crit = float(self.critical_dt())
        self._auto_dt, self._auto_step = dt, self.steps
        return self._auto_crit, self._auto_dt, self._auto_step

    def record_compiled_step(self, dt: float, active: str | None) -> None:
        """Bookkeeping after a compiled caller (tissue/compiled.py) stepped the model in place at
        least once: the last step's ``dt`` (s) and, for integrator "auto", the concrete integrator
        it took (``active``). The caller sets ``time`` and ``steps`` itself."""
        self._last_dt = dt
        if active is not None:
            self._active = active

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
        """Estimated largest stable dt (s) for the explicit integrator, the raw estimate with NO
        safety factor (inf if unconditionally stable). Use :meth:`stable_dt` to choose a step."""

    def stable_dt(self) -> float:
        """``DT_SAFETY * critical_dt()`` (s): the step the explicit integrator may take (the only
        place a safety factor is applied)."""
        return DT_SAFETY * float(self.critical_dt())

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
        self.integrated_external_forces = np.zeros_like(self.positions)
        self.time = 0.0
        self.steps = 0
        self.guard.reset()
        if self.integrator == "auto":
            self._active, self._auto_dt, self._auto_step, self._auto_crit = None, float("nan"), 0, float("nan")
        self._reset_state()
        self.notify_changed()

    def _reset_state(self) -> None:
        """Hook: clear model-specific internal state (viscoelastic branches, history...)."""

    def step_state(self) -> tuple:
        """A copy of everything one step changes (positions, velocities, the integrated forces, the
        clock and step count, the guard's state and the model's own, :meth:`_step_state_arrays`), for
        :meth:`restore_step_state`: the scene solves a step again from where it started."""
        energy, good_pos, good_vel, good_time = self.guard.state()
        return (self.positions.copy(), self.velocities.copy(), self.integrated_external_forces.copy(),
                self.external_forces, self.time, self.steps, energy,
                None if good_pos is None else good_pos.copy(), None if good_vel is None else good_vel.copy(),
                good_time, [a.copy() for a in self._step_state_arrays()])

    def restore_step_state(self, state: tuple, positions: np.ndarray) -> None:
        """Back to ``state`` (:meth:`step_state`), in place (no array is replaced), with the node
        ``positions`` (N,3) m instead of the saved ones: the point the next step linearises about."""
        _, vel, integrated, external, time, steps, energy, good_pos, good_vel, good_time, extra = state
        np.copyto(self.positions, positions)
        np.copyto(self.velocities, vel)
        np.copyto(self.integrated_external_forces, integrated)
        self.external_forces = external
        self.time, self.steps = time, steps
        self.guard.load_state(energy, good_pos, good_vel, good_time)
        for dst, src in zip(self._step_state_arrays(), extra):
            np.copyto(dst, src)

    def _step_state_arrays(self) -> list:
        """Hook: the model's own arrays a step changes (a history, a hereditary integral), in place."""
        return []

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
