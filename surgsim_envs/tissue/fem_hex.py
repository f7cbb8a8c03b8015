"""``fem_hex``: quasi-static small-strain FEM on the box cells of a lattice, each an 8-node hexahedron
with incompatible bending modes (:mod:`surgsim_envs.tissue.hex_elements`), for layered bodies whose
thin stiff layers bend (a skin on a soft fat).

Linear tets need several cells through a bending layer and a fine in-plane lattice: LayeredPalpation-v0's
continuum wall in tets (``fem_static``) meets the task's 20 % only at 2 mm (21,607 nodes). The same
lattice's box cells as hexahedra with incompatible modes represent bending exactly on box elements
(docs/models/fem_hex.md). The model takes a tensor-product lattice (``geometry.box_volume``, the
walls of ``geometry.wall_lattice``): its material fields live on the box cells (``element_centroids``
are the cells' centres, ``scale_material`` masks are per cell); a cell's material is its tets' label's.
A region that cuts through cells (a stiff nodule) is given per Gauss point
(``material_points``, ``scale_material_at_points``): a cut cell integrates each of its 8 points with
that point's Young's modulus, so the inclusion's stiffness follows its volume within the cell where
a rule on the cell's centre would take the whole cell or nothing.

Solved as ``fem_static``: the stiffness on the free dofs is factorised once per material
(SuperLU, or MKL PARDISO through the optional pypardiso with ``solver="auto"``), the equilibrium
under loads on a few nodes comes from their cached compliance columns (:meth:`compliance_block`,
:meth:`apply_axial_forces`, :meth:`apply_nodal_forces`: capability ``condensed_compliance``), a full
load by one back-substitution (:meth:`static_solve`). Elastic only: a material that relaxes
(``relax_fraction`` > 0) is taken at its relaxed moduli, E (1 - relax_fraction). It has no contact
stiffness in its step (no ``implicit_contact``), so the contact scenes refuse it; a task that
presses it solves its contact on the compliance block. Units: m, Pa, N.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.box_cells import box_cells
from surgsim_envs.tissue.base import ELEMENT_FIELDS, TissueModel
from surgsim_envs.tissue.compliance import DEFAULT_CACHE_MB, SOLVERS, CondensedCompliance
from surgsim_envs.tissue.guard import StabilityGuard
from surgsim_envs.tissue.hex_elements import GAUSS_POINTS, HexAssembly


class HexStaticModel(TissueModel):
    """Quasi-static hexahedra with incompatible modes on a box lattice (module docstring).

    cache_mb: memory (MB) for cached compliance columns (least recently used evicted beyond it).
    solver: ``"superlu"`` (default), ``"pardiso"`` (needs pypardiso) or ``"auto"``.
    """

    name: ClassVar[str] = "fem_hex"
    summary: ClassVar[str] = ("quasi-static small-strain FEM on box hexahedra with incompatible bending modes "
                              "(Wilson-Taylor): thin stiff layers bend; prefactored, condensed compliance")
    integrators: ClassVar[tuple[str, ...]] = ("quasi_static",)
    capabilities: ClassVar[frozenset[str]] = frozenset({"forces", "quasi_static", "static_solve",
                                                        "subsurface_stiffness", "condensed_compliance"})
    material_fields: ClassVar[tuple[str, ...]] = ("young", "poisson", "density", "relax_fraction")

    def __init__(self, volume, material="liver", *, cache_mb: float = DEFAULT_CACHE_MB, solver: str = "superlu",
                 **base_kwargs):
        self.cells = box_cells(volume)          # before the base class: the fields live on the cells
        self.cache_mb = validate.positive(cache_mb, "fem_hex: cache_mb", unit="MB",
                                          fix="the memory of cached compliance columns, e.g. 256")
        self.solver = validate.choice(solver, "fem_hex: solver", SOLVERS,
                                      fix="'superlu', 'pardiso' (needs pypardiso) or 'auto'")
        if base_kwargs.get("guard") is None:   # a factorised SPD solve cannot diverge (as fem_static)
            base_kwargs["guard"] = StabilityGuard(check_inversion=False, check_every=100)
        self._comp: CondensedCompliance | None = None
        self._u0: np.ndarray | None = None
        self._assembly: HexAssembly | None = None
        #: (cells (M,), (M, 8) Gauss-point factors of mean 1) where Young's modulus varies within a cell
        self._point_shape: tuple[np.ndarray, np.ndarray] | None = None
        super().__init__(volume, material, **base_kwargs)
        self._stiffness = None
        self._on_material_changed("young")

    # ------------------------------------------------------------------------------------------
    # Fields on the box cells
    def _build_fields(self) -> dict[str, np.ndarray]:
        out = {}
        for key in ELEMENT_FIELDS:
            arr = np.full(len(self.cells.hexes), float(getattr(self.material, key)))
            for label, mat in self.region_materials.items():
                arr[self.cells.labels == label] = float(getattr(mat, key))
            out[key] = arr
        return out

    def _lumped_masses(self) -> np.ndarray:
        """Row-sum lumped mass (kg): each cell gives rho V / 8 to its corners."""
        m = np.zeros(self.volume.n_nodes)
        share = self.fields["density"] * self.cells.sizes.prod(axis=1) / 8.0
        np.add.at(m, self.cells.hexes.reshape(-1), np.repeat(share, 8))
        return m

    def element_centroids(self) -> np.ndarray:
        """(H, 3) m rest centres of the box cells (the elements that carry the fields)."""
        return self.cells.centroids.copy()

    def element_vertices(self) -> np.ndarray:
        """(H, 8, 3) m rest corners of the box cells."""
        return self.rest_positions[self.cells.hexes]

    def material_points(self) -> np.ndarray:
        """(H, 8, 3) m rest positions of each cell's 2 x 2 x 2 Gauss points, where its stiffness is
        integrated (:data:`~surgsim_envs.tissue.hex_elements.GAUSS_POINTS` order)."""
        return self.cells.centroids[:, None, :] + 0.5 * self.cells.sizes[:, None, :] * GAUSS_POINTS[None]

    def scale_material_at_points(self, name: str, factors) -> None:
        """Scale field ``name`` by ``factors`` (H, 8) per Gauss point, relative to its value at build.
        A cell whose points differ (an inclusion's boundary crosses it) is integrated with each
        point's Young's modulus, its incompatible modes condensed with them; its field holds the
        points' mean (its volume average: the points weigh alike on a box). Only ``young`` may vary
        within a cell; other fields need equal factors across a cell's points."""
        self._check_field_name(name)
        f = self._point_factors(name, factors)
        mean = f.mean(axis=1)
        mixed = np.flatnonzero(np.any(f != f[:, :1], axis=1))
        if len(mixed) and name != "young":
            raise ConfigError(f"fem_hex: only 'young' may vary within a cell; {name!r} factors differ across the "
                              f"Gauss points of {len(mixed)} cell(s) (give one value per cell: scale_material)")
        values = self._fields0[name] * mean
        shape = (mixed, f[mixed] / mean[mixed, None]) if len(mixed) else None
        previous = self._point_shape
        self._point_shape = shape if name == "young" else previous
        try:
            self._apply_field(name, values)
        except Exception:
            self._point_shape = previous
            raise

    def scale_material(self, name: str = "young", factor=1.0, mask=None) -> None:
        """As the contract's (per cell); a ``young`` given per cell makes every cell uniform again."""
        previous = self._point_shape
        if name == "young":
            self._point_shape = None
        try:
            super().scale_material(name, factor, mask)
        except Exception:
            self._point_shape = previous
            raise

    def set_field(self, name: str, values) -> None:
        """As the contract's (per cell); a ``young`` given per cell makes every cell uniform again."""
        previous = self._point_shape
        if name == "young":
            self._point_shape = None
        try:
            super().set_field(name, values)
        except Exception:
            self._point_shape = previous
            raise

    def _on_material_changed(self, name: str) -> None:
        young, nu = self.fields["young"], self.fields["poisson"]
        if np.any(young <= 0) or np.any(nu <= -1.0) or np.any(nu >= 0.5):
            raise ConfigError("fem_hex needs E > 0 Pa and -1 < nu < 0.5 in every cell (use nu <= 0.499)")
        relaxed = young * (1.0 - self.fields["relax_fraction"])
        if self._assembly is None or not np.array_equal(self._assembly.poisson, nu):
            self._assembly = HexAssembly(self.n_nodes, self.cells.hexes, self.cells.sizes, nu)
        points = None
        if self._point_shape is not None:   # cells whose Young's modulus varies over their Gauss points
            cells, shape = self._point_shape
            points = (cells, relaxed[cells, None] * shape)
        self._stiffness = self._assembly.stiffness(relaxed, points)
        self._comp, self._u0 = None, None

    def _on_fixed_changed(self) -> None:
        self._comp, self._u0 = None, None

    # ------------------------------------------------------------------------------------------
    def stiffness_matrix(self, relaxed: bool = True, clamp: bool = False):
        """K (3N x 3N, N/m), every dof (the fixed ones included)."""
        return self._stiffness

    def compliance(self) -> CondensedCompliance:
        """The factorised stiffness with its column cache (rebuilt when the material or the fixed nodes change)."""
        if self._comp is None:
            free = ~np.repeat(self.fixed, 3)
            if free.all():
                raise ConfigError("fem_hex needs fixed nodes (a free body has rigid modes): pass fixed=... or "
                                  "call set_fixed(nodes)")
            self._comp = CondensedCompliance(self._stiffness, free, cache_mb=self.cache_mb, solver=self.solver)
        return self._comp

    def _base_displacement(self) -> np.ndarray:
        """u0 (3N,) m: the equilibrium under the fixed nodes' targets and gravity alone."""
        if self._u0 is None:
            comp = self.compliance()
            uc = np.zeros(3 * self.n_nodes)
            fx = self.fixed
            uc.reshape(-1, 3)[fx] = self.fixed_targets[fx] - self.rest_positions[fx]
            load = (self.masses[:, None] * self.gravity[None, :]).reshape(-1) - self._stiffness @ uc
            self._u0 = uc + comp.solve(np.where(comp.free, load, 0.0))
        return self._u0

    def _set_state(self, u: np.ndarray, forces: np.ndarray) -> np.ndarray:
        self.positions = self.rest_positions + u.reshape(-1, 3)
        self.velocities = np.zeros_like(self.positions)
        self.external_forces = forces
        self.integrated_external_forces = forces.copy()
        return self.positions.copy()

    def static_solve(self, forces=None, stiffness=None, **kwargs) -> np.ndarray:
        """Equilibrium positions (N,3) m under ``forces`` (N,3) N (default: the last ones) and the fixed
        nodes' targets, by one back-substitution; updates ``positions`` and returns a copy."""
        if stiffness is not None or kwargs:
            raise ConfigError("fem_hex.static_solve takes only forces (no contact stiffness, no options)")
        f = self.external_forces if forces is None else np.asarray(forces, dtype=np.float64)
        if f.shape != self.positions.shape or not np.all(np.isfinite(f)):
            raise ConfigError(f"forces must be a finite array of shape {self.positions.shape}, got {f.shape}")
        comp = self.compliance()
        u = self._base_displacement() + comp.solve(np.where(comp.free, f.reshape(-1), 0.0))
        return self._set_state(u, np.array(f))

    def _advance(self, dt: float, forces: np.ndarray, stiffness) -> None:
        if stiffness is not None and np.any(np.asarray(stiffness) != 0):
            raise ConfigError("fem_hex has no contact stiffness in its step (no implicit_contact); solve a contact "
                              "on compliance_block(...) instead")
        self.static_solve(forces)

    def _free_indices(self, nodes, what: str) -> np.ndarray:
        idx = self._as_indices(nodes, what)
        if np.any(self.fixed[idx]):
            raise ConfigError(f"fem_hex.{what}: nodes {idx[self.fixed[idx]][:5].tolist()} are fixed; pass free "
                              "nodes only")
        return idx

    def compliance_block(self, nodes, axis: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(W, u0) of free ``nodes`` (m,): W (3m, 3m) m/N their dofs' displacement per unit force on
        them, u0 (3m,) m their displacement with no force; with ``axis`` (0, 1, 2) that axis only, W
        (m, m) and u0 (m,), from single-axis columns (see ``fem_static.compliance_block``)."""
        idx = self._free_indices(nodes, "compliance_block")
        comp, u0 = self.compliance(), self._base_displacement()
        if axis is not None:
            ax = validate.integer(axis, "fem_hex.compliance_block axis", lo=0, hi=2, fix="0, 1 or 2 (2 = z)")
            return comp.axis_block(idx, ax), u0[3 * idx + ax].copy()
        return comp.block(idx, comp.slots(idx)), u0[(3 * idx[:, None] + np.arange(3)).reshape(-1)].copy()

    def apply_axial_forces(self, nodes, forces, axis: int) -> np.ndarray:
        """The equilibrium under forces (m,) N along ``axis`` on free ``nodes`` alone, from their
        single-axis compliance columns. Returns the positions (N,3) m (a copy)."""
        ax = validate.integer(axis, "fem_hex.apply_axial_forces axis", lo=0, hi=2, fix="0, 1 or 2 (2 = z)")
        idx = self._free_indices(nodes, "apply_axial_forces")
        f = np.asarray(forces, dtype=np.float64)
        if f.shape != (len(idx),) or not np.all(np.isfinite(f)):
            raise ConfigError(f"fem_hex.apply_axial_forces: forces must be a finite ({len(idx)},) array (N), "
                              f"got shape {f.shape}")
        comp = self.compliance()
        u = self._base_displacement().copy()
        if len(idx):
            comp.axis_response(comp.axis_slots(idx, ax), f, ax, u)
        full = np.zeros_like(self.positions)
        full[idx, ax] = f
        return self._set_state(u, full)

    def apply_nodal_forces(self, nodes, forces) -> np.ndarray:
        """The equilibrium under forces (m,3) N on free ``nodes`` alone, from their cached compliance
        columns. Returns the positions (N,3) m (a copy)."""
        idx = self._free_indices(nodes, "apply_nodal_forces")
        f = np.asarray(forces, dtype=np.float64)
        if f.shape != (len(idx), 3) or not np.all(np.isfinite(f)):
            raise ConfigError(f"fem_hex.apply_nodal_forces: forces must be a finite ({len(idx)}, 3) array (N), "
                              f"got shape {f.shape}")
        comp = self.compliance()
        u = self._base_displacement().copy()
        if len(idx):
            comp.response(comp.slots(idx), f, u)
        full = np.zeros_like(self.positions)
        full[idx] = f
        return self._set_state(u, full)

    # ------------------------------------------------------------------------------------------
    def internal_forces(self) -> np.ndarray:
        """(N,3) N elastic nodal forces, -K u."""
        u = (self.positions - self.rest_positions).reshape(-1)
        return -(self._stiffness @ u).reshape(-1, 3)

    def elastic_energy(self) -> float:
        u = (self.positions - self.rest_positions).reshape(-1)
        return 0.5 * float(u @ (self._stiffness @ u))

    def critical_dt(self) -> float:
        """No explicit integrator: unconditionally stable (inf)."""
        return math.inf

    def describe(self) -> dict:
        out = super().describe()
        out.update(elements=int(len(self.cells.hexes)), element="hexahedron, incompatible modes",
                   cache_mb=self.cache_mb, solver=self.solver)
        return out


__all__ = ["HexStaticModel"]
