"""Heterogeneous multi-layer tissue with constrained local static integration (Lin et al. 2008, section 2.4).

The volume is a :class:`~surgsim_envs.geometry.layers.LayeredVolume`: a lattice whose nodes carry
material flags and whose springs join each node to its six direct neighbours (the neighbouring
bounding box, NBB, Fig. 2.11). Each spring is linear in the displacements (eq. 2.8):

    f_i = sum_j K_ij [(P_j - P_i) - (P0_j - P0_i)]                              (N)

with ``K_ij = G_L A_ij / L0_ij``: ``A_ij`` the cross-section the spring represents (a quarter cell
face per kept cell around the edge), ``L0_ij`` its rest length and ``G_L = E / (2 (1 - nu^2))`` of
the spring's material (the paper's rules, :mod:`surgsim_envs.geometry.layers`). In the continuum
limit this is ``G_L laplace(u) + g = 0`` per component; ``G_L = G / (1 - nu)`` makes the stiffness
of a rigid flat punch on a half-space (Laplace: ``F = 4 a G_L d``) equal Boussinesq's
(``F = 2 a E d / (1 - nu^2)``). See docs/models/layered.md.

No inertia (quasi-static): every step solves the local equilibrium of each ACTIVE node (eq. 2.9)
with its neighbours held, clamped into its NBB shrunk by the extreme lengths
``lmin = (1 - max_compression) L0`` (so nodes never pass their neighbours: no interpenetration of
layers), and iterates (eq. 2.10) until no node moves more than ``x_tol`` nor changes a spring force
by more than ``f_tol``. Active nodes: the loaded ones and those a moving neighbour disturbs; the
set grows and shrinks with the contact. A spring at its extreme length is rigid and passes the
force on to the next node, recursively (force accumulation, eq. 2.5, Fig. 2.10). Rigid materials
(bone) are fixed. The force on a contact (Dirichlet) node is the interpolated spring force
:meth:`contact_force`; with scene contact, the integrated contact force (``implicit_contact``).
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.layers import DIRECTIONS, LayeredVolume, layered_from_grid
from surgsim_envs.tissue import layered_kernels as kern
from surgsim_envs.tissue.base import TissueModel

#: default largest compressive strain of a spring before it turns rigid (extreme length = 0.2 L0)
MAX_COMPRESSION = 0.8
#: default force threshold (N): a node whose update changes a neighbour's spring force by less stays idle
F_TOL = 1e-6
#: default displacement threshold (m)
X_TOL = 1e-7
#: default over-relaxation of the local solve (projected SOR; 1.0 is the paper's plain iteration)
OMEGA = 1.8
#: per-step solvers (class docstring)
SOLVERS = ("local", "prefactored")
#: node stiffness forms: the paper's scalar NBB springs (eq. 2.8) or the snapped cells' elasticity
#: (:mod:`surgsim_envs.tissue.layered_elastic`)
STIFFNESS_FORMS = ("paper", "elastic")
#: default width (m) of the ring of lattice columns around the contact footprint the "prefactored"
#: solver writes each step (at least one lattice spacing: the contact nodes' neighbours)
BLOCK_RADIUS = 0.002
#: default node updates per step (bounds the step time; what is left continues next step)
MAX_UPDATES = 2_000_000


def laplace_modulus(young: np.ndarray, poisson: np.ndarray) -> np.ndarray:
    """G_L = E / (2 (1 - nu^2)) (Pa): the spring modulus whose half-space punch stiffness equals elasticity's."""
    return np.asarray(young, dtype=np.float64) / (2.0 * (1.0 - np.asarray(poisson, dtype=np.float64) ** 2))


class LayeredModel(TissueModel):
    """Lin et al. 2008's heterogeneous layered tissue (module docstring).

    Parameters
    ----------
    volume: a LayeredVolume (:func:`surgsim_envs.geometry.layers.layered_volume`,
        :mod:`surgsim_envs.geometry.anatomy`). Its materials come from the volume's layers; the
        ``material`` argument is ignored except for reports (pass the base material).
    max_compression: largest compressive strain of a spring in (0, 1) before it becomes rigid.
    f_tol: N, force threshold of the active set; x_tol: m, displacement threshold.
    max_updates: node updates per step (the work left over continues in the next step).
    omega: over-relaxation in [1, 2) of each local move (1 = the paper's plain iteration).
    solver: "local" (the work-list local iteration each step) or "prefactored" (the springs of all
        nodes factorised once, contact nodes by their reactions: the exact all-node solution with
        the nodes within ``block_radius`` m of the contact written each step, springs at their
        extreme length as rigid links with their own reactions; steps with external forces use the
        local iteration).
    prefetch_rows: with "prefactored", back-solve the compliance rows of the surface around the
        contact in a background thread (a second core) so a node joining the contact does not
        wait for its back-solve; off by default (the step stays on one core).
    **base_kwargs: fixed, gravity (ignored: quasi-static without body load), guard.
    """

    name: ClassVar[str] = "layered"
    summary: ClassVar[str] = ("heterogeneous layered tissue (Lin et al. 2008): NBB springs from material layers, "
                              "constrained local static integration on active nodes, force accumulation")
    integrators: ClassVar[tuple[str, ...]] = ("local_static",)
    capabilities: ClassVar[frozenset] = frozenset({"forces", "implicit_contact", "quasi_static", "static_solve",
                                                   "unstructured_mesh", "subsurface_stiffness"})

    def __init__(self, volume, material=None, *, max_compression: float = MAX_COMPRESSION, f_tol: float = F_TOL,
                 x_tol: float = X_TOL, max_updates: int = MAX_UPDATES, omega: float = OMEGA, solver: str = "local",
                 block_radius: float = BLOCK_RADIUS, prefetch_rows: bool = False, region_materials=None,
                 stiffness: str = "paper", **base_kwargs):
        if not isinstance(volume, LayeredVolume):  # a plain lattice volume: one material per region label
            from surgsim_envs.geometry.volume import Volume
            from surgsim_envs.materials import get_material

            if not isinstance(volume, Volume):
                raise ConfigError(f"model 'layered' needs a LayeredVolume (surgsim_envs.geometry.layers.layered_volume "
                                  f"or an anatomy organ such as 'abdominal_wall'), got {type(volume).__name__}")
            base = get_material(material if material is not None else "liver")
            mats = {int(k): base for k in np.unique(volume.labels)}
            mats.update({int(k): get_material(v) for k, v in (region_materials or {}).items()})
            try:
                volume = layered_from_grid(volume, mats)
            except ConfigError:   # not a tensor grid (a snapped organ lattice, a user mesh): NBB from its edges
                from surgsim_envs.geometry.layered_mesh import layered_from_mesh

                volume = layered_from_mesh(volume, mats)
            material, region_materials = base, None
        if not (0.0 < float(max_compression) < 1.0):
            raise ConfigError(f"layered: max_compression must be in (0, 1), got {max_compression!r}")
        validate.positive(f_tol, "layered: f_tol", unit="N", fix="the force threshold of the active set")
        validate.positive(x_tol, "layered: x_tol", unit="m", fix="the displacement threshold of the iteration")
        if not (isinstance(omega, (int, float)) and 1.0 <= omega < 2.0):
            raise ConfigError(f"layered: omega must be in [1, 2) (1 = plain local static iteration), got {omega!r}")
        if stiffness not in STIFFNESS_FORMS:
            raise ConfigError(f"layered: stiffness must be one of {STIFFNESS_FORMS} ('paper': eq. 2.8 scalar springs; "
                              f"'elastic': linear elasticity of the snapped cells), got {stiffness!r}")
        if solver not in SOLVERS:
            raise ConfigError(f"layered: solver must be one of {SOLVERS}, got {solver!r}")
        validate.positive(block_radius, "layered: block_radius", unit="m",
                          fix="the nodes within it of the contact are written each step")
        validate.integer(max_updates, "layered: max_updates", lo=1, fix="give a positive integer")
        if region_materials is None:
            present = set(np.unique(volume.labels).tolist())  # a layer thinner than the lattice may own no tet
            region_materials = {k: volume.material_table[m] for k, m in enumerate(volume.layer_names) if k in present}
        if material is None:
            material = volume.material_table[volume.layer_names[0]]
        super().__init__(volume, material, region_materials=region_materials, **base_kwargs)
        self.max_compression = float(max_compression)
        self.f_tol, self.x_tol, self.max_updates = float(f_tol), float(x_tol), int(max_updates)
        self.omega = float(omega)
        self.solver, self.block_radius, self.prefetch_rows = solver, float(block_radius), bool(prefetch_rows)
        n = self.n_nodes
        self.nbr = np.ascontiguousarray(volume.neighbours, dtype=np.int32)
        X = self.rest_positions
        L0 = np.zeros((n, 6))
        sep = np.zeros((n, 6))
        for d in range(6):
            j = self.nbr[:, d]
            ok = j >= 0
            L0[ok, d] = np.linalg.norm(X[j[ok]] - X[ok], axis=1)
            sep[ok, d] = np.abs(X[j[ok], d // 2] - X[ok, d // 2])
        if np.any(L0[self.nbr >= 0] <= 0):
            raise ConfigError(f"layered: volume '{volume.name}' has coincident neighbour nodes; remesh")
        self.rest_lengths = L0
        self.lmin = np.ascontiguousarray((1.0 - self.max_compression) * sep)
        self._spring_tets = self._map_springs_to_tets()
        self._build_g = laplace_modulus(self.fields["young"], self.fields["poisson"])
        self.kk_build = self._paper_springs()
        self.kk = self.kk_build.copy()
        self.stiffness_form = stiffness
        self._elastic = stiffness == "elastic"
        self._elastic_k = self._build_elastic_k() if self._elastic else None
        self._ec = None
        # rigid materials (bone) never move
        rigid = volume.rigid_nodes
        if len(rigid):
            self.set_fixed(np.union1d(rigid, np.flatnonzero(self.fixed)).astype(np.int64))
        self.rigid_nodes = rigid
        self._alloc()

    # ------------------------------------------------------------------------------------------
    def _paper_springs(self) -> np.ndarray:
        """K_ij (N,6) N/m from the volume's spring materials (paper's rules)."""
        vol = self.volume
        tab = vol.material_table
        gl = np.array([laplace_modulus(tab[m].young, tab[m].poisson) for m in vol.material_names])
        code = vol.spring_material
        g = np.zeros(code.shape)
        direct = code >= 0
        g[direct] = gl[code[direct]]
        series = code <= -2
        if series.any():
            own = -2 - code[series]
            i_idx, d_idx = np.nonzero(series)
            other = vol.node_material[self.nbr[i_idx, d_idx]]
            ga, gb = gl[own], gl[other]
            g[series] = 2.0 * ga * gb / (ga + gb)
        kk = np.zeros_like(g)
        ok = self.nbr >= 0
        kk[ok] = g[ok] * vol.spring_area[ok] / self.rest_lengths[ok]
        return np.ascontiguousarray(kk)

    def _build_elastic_k(self):
        """3N x 3N elastic stiffness of the snapped cells (``stiffness="elastic"``) from the tet fields."""
        from surgsim_envs.tissue.layered_elastic import cell_of_tets, elastic_stiffness

        if getattr(self, "_tet_cells", None) is None:
            self._tet_cells = cell_of_tets(self.volume.lattice_index, self.volume.tets)
        return elastic_stiffness(self.rest_positions, self.volume.tets, self.fields["young"], self.fields["poisson"],
                                 self._tet_cells)

    def _elastic_solve(self, ext: np.ndarray, kc: np.ndarray, dt: float | None) -> int:
        """``stiffness="elastic"``: the all-node constrained equilibrium (ElasticContact); returns
        the number of nodes written."""
        from surgsim_envs.tissue.layered_elastic import ElasticContact

        ec = self._ec
        if ec is None or not ec.valid():
            ec = self._ec = ElasticContact(self)
        xs = self._x.copy()
        settled = ec.solve(ext, kc, xs)
        nodes = np.flatnonzero(~self.fixed)
        if dt is not None and dt > 0:
            self.velocities[nodes] = (self._x[nodes] - xs[nodes]) / dt
        self._touched[:len(nodes)] = nodes
        self._n_touched = len(nodes)
        self.last_updates, self.last_sweeps, self.last_active = len(nodes), 1, len(nodes)
        self.unconverged = 0 if settled else self.n_nodes
        self.last_active_set_iterations = ec.last_iterations
        self._moved_fixed = np.zeros(0, dtype=np.int64)
        self._n_queue = 0
        self._ief_nonzero = True
        self.external_forces = ext
        return len(nodes)

    def _map_springs_to_tets(self):
        """(spring rows, tet ids) pairs: the tets sharing each NBB spring's edge (for scale_material)."""
        n = self.n_nodes
        tets = self.volume.tets.astype(np.int64)
        pairs = np.stack([tets[:, [0, 0, 0, 1, 1, 2]].ravel(), tets[:, [1, 2, 3, 2, 3, 3]].ravel()], axis=1)
        pairs.sort(axis=1)
        tkey = pairs[:, 0] * n + pairs[:, 1]
        tet_of = np.repeat(np.arange(len(tets)), 6)
        order = np.argsort(tkey, kind="stable")
        tkey, tet_of = tkey[order], tet_of[order]
        i_idx, d_idx = np.nonzero(self.nbr >= 0)
        j = self.nbr[i_idx, d_idx].astype(np.int64)
        skey = np.minimum(i_idx, j) * n + np.maximum(i_idx, j)
        lo = np.searchsorted(tkey, skey, side="left")
        hi = np.searchsorted(tkey, skey, side="right")
        counts = hi - lo
        rows = np.repeat(np.arange(len(skey)), counts)
        starts = np.repeat(lo - np.cumsum(np.r_[0, counts[:-1]]), counts)
        tets_per = tet_of[np.arange(counts.sum()) + starts]
        return i_idx, d_idx, rows, tets_per, counts

    def _update_springs(self) -> None:
        """Scale every spring by the mean change of G_L of the tets around it (scale_material/set_field)."""
        i_idx, d_idx, rows, tets_per, counts = self._spring_tets
        ratio = laplace_modulus(self.fields["young"], self.fields["poisson"]) / self._build_g
        s = np.bincount(rows, weights=ratio[tets_per], minlength=len(i_idx))
        factor = np.where(counts > 0, s / np.maximum(counts, 1), 1.0)
        kk = self.kk_build.copy()
        kk[i_idx, d_idx] *= factor
        self.kk = np.ascontiguousarray(kk)
        self._materialise()
        if self._elastic:
            self._elastic_k = self._build_elastic_k()
            self._ec = None
        self._lap_cache = None
        self._pc = None
        self._seed_all = True

    def scale_material(self, name: str = "young", factor=1.0, mask=None) -> None:
        """Multiply tet field ``name`` by ``factor`` (scalar or (T,)) where ``mask`` (T,) is True,
        relative to its value at build; the springs follow (contract v2)."""
        if name not in self.fields:
            raise ConfigError(f"layered: unknown material field {name!r}; fields: {sorted(self.fields)}")
        base = getattr(self, "_field_build", None)
        if base is None:
            self._field_build = base = {k: v.copy() for k, v in self.fields.items()}
        t = len(self.volume.tets)
        f = np.broadcast_to(np.asarray(factor, dtype=np.float64), (t,))
        m = np.ones(t, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        if m.shape != (t,):
            raise ConfigError(f"layered: mask must have shape ({t},), got {m.shape}")
        if not np.all(np.isfinite(f)) or np.any(f[m] <= 0):
            raise ConfigError("layered: scale factors must be finite and > 0")
        self.fields[name] = np.where(m, base[name] * f, self.fields[name])
        self._update_springs()

    def set_field(self, name: str, values) -> None:
        """Set tet field ``name`` to absolute (T,) values; the springs follow."""
        if name not in self.fields:
            raise ConfigError(f"layered: unknown material field {name!r}; fields: {sorted(self.fields)}")
        v = np.asarray(values, dtype=np.float64)
        if v.shape != self.fields[name].shape or not np.all(np.isfinite(v)):
            raise ConfigError(f"layered: {name} values must be finite with shape {self.fields[name].shape}")
        if getattr(self, "_field_build", None) is None:
            self._field_build = {k: x.copy() for k, x in self.fields.items()}
        self.fields[name] = v.copy()
        self._update_springs()

    def __getstate__(self):
        """Copies and pickles drop the prefactored solver's factorisation (rebuilt on the next step);
        the positions are written out first."""
        self._materialise()
        state = self.__dict__.copy()
        state["_pc"] = None
        state["_ec"] = None
        return state

    # ------------------------------------------------------------------------------------------
    # lazy positions: the prefactored step writes only the nodes near the contact; the others are
    # recovered from its solution when read
    _lazy: bool = False
    _pc = None

    @property
    def positions(self) -> np.ndarray:
        """(N,3) m node positions (written out from the prefactored solution if it left some stale)."""
        if self._lazy:
            self._materialise()
        return self._x

    @positions.setter
    def positions(self, value) -> None:
        self._lazy = False
        self._x = value

    @property
    def n_nodes(self) -> int:
        return len(self.rest_positions)

    def _materialise(self) -> None:
        if self._lazy:
            self._lazy = False
            self._pc.materialise()

    def _drop_prefactored(self) -> None:
        self._materialise()
        self._pc = None

    def node_positions(self, nodes) -> np.ndarray:
        """(K,3) m positions of ``nodes`` (evaluated from the prefactored solution for stale rows,
        without writing the rest of the volume)."""
        idx = self._as_indices(nodes, "nodes")
        if not self._lazy:
            return self._x[idx].copy()
        return self._pc.positions_of(idx)

    # ------------------------------------------------------------------------------------------
    def _alloc(self) -> None:
        n = self.n_nodes
        self.push = np.zeros((n, 6))
        self._xs = np.zeros((n, 3))
        self._tstamp = np.full(n, -1, dtype=np.int64)
        self._qstamp = np.full(n, -1, dtype=np.int64)
        self._queue = np.zeros(7 * n + 8, dtype=np.int64)
        self._nxt = np.zeros(7 * n + 8, dtype=np.int64)
        self._n_queue = 0
        self._qid = 0
        self._touched = np.zeros(n, dtype=np.int64)
        self._n_touched = 0
        self._loaded = np.zeros(n, dtype=np.int64)
        self._loaded_prev = np.zeros(n, dtype=np.int64)
        self._n_loaded = 0
        self._moved_fixed = np.zeros(0, dtype=np.int64)
        self._seed_all = False
        self._ief_nonzero = False
        self.integrated_external_forces = np.zeros((n, 3))
        self._zero_kc = np.zeros(n)
        self._xstamp = np.zeros(n, dtype=np.int64)
        self._xversion = 0
        # the model's own zero load (read-only): a step without forces on it may take the fast path
        self._ext_zero = np.zeros((n, 3))
        self._ext_zero.flags.writeable = False
        self.external_forces = self._ext_zero
        self.last_updates = 0
        self.last_sweeps = 0
        self.last_active = 0
        self.unconverged = 0

    def _reset_state(self) -> None:
        self._alloc()

    def set_fixed(self, nodes, targets=None) -> None:
        """Dirichlet nodes (contact points pressed by a kinematic tool, anchors); moving them
        activates their neighbours."""
        idx = self._as_indices(nodes, "fixed nodes")
        pc = self._pc
        if pc is not None and pc.anchor[idx].any():   # an anchor moved: the factorisation no longer applies
            t = self.rest_positions[idx] if targets is None else np.broadcast_to(np.asarray(targets, float), (len(idx), 3))
            if not np.array_equal(np.asarray(t)[pc.anchor[idx]], self.rest_positions[idx[pc.anchor[idx]]]):
                self._drop_prefactored()
        if targets is not None and len(idx) and hasattr(self, "_moved_fixed") and self.fixed[idx].all():
            # held nodes moved (a tool's contact each step): the Dirichlet set is unchanged
            t = np.asarray(targets, dtype=np.float64).reshape(-1, 3)
            if len(t) not in (1, len(idx)) or not np.all(np.isfinite(t)):
                raise ConfigError(f"targets must be finite with shape ({len(idx)}, 3) or (3,), got {np.shape(targets)}")
            self.fixed_targets[idx] = t
            self._x[idx] = self.fixed_targets[idx]
            self.velocities[idx] = 0.0
        else:
            lazy, self._lazy = self._lazy, False   # write the targets without writing out stale rows
            try:
                super().set_fixed(idx, targets)
            finally:
                self._lazy = lazy
        if hasattr(self, "_moved_fixed"):
            self._moved_fixed = np.concatenate([self._moved_fixed, idx])

    def release(self, nodes=None) -> None:
        """Free ``nodes`` (all if None) except rigid-material nodes; they relax at the next step."""
        idx = np.flatnonzero(self.fixed) if nodes is None else self._as_indices(nodes, "released nodes")
        keep = np.isin(idx, getattr(self, "rigid_nodes", np.zeros(0, np.int64)))
        if self._pc is not None and self._pc.anchor[idx[~keep]].any():   # an anchor released: refactorise
            self._drop_prefactored()
        super().release(idx[~keep])
        if hasattr(self, "_moved_fixed"):
            self._moved_fixed = np.concatenate([self._moved_fixed, idx[~keep]])

    # ------------------------------------------------------------------------------------------
    def _advance(self, dt: float, forces: np.ndarray, stiffness: np.ndarray | None) -> None:
        self.solve(forces, stiffness, dt=dt)

    def _prefactored_solver(self):
        """The "prefactored" solver (built on first use and when the anchors changed)."""
        from surgsim_envs.tissue.layered_prefactored import PrefactoredContact

        pc = self._pc
        if pc is None or (self.steps % pc.refresh == 0 and not pc.valid()):
            self._materialise()
            pc = self._pc = PrefactoredContact(self, self.block_radius, prefetch=self.prefetch_rows)
        return pc

    def _contacts(self, pc) -> np.ndarray:
        fx = self._fixed_idx
        return fx[~pc.anchor[fx]]

    def step(self, dt: float, forces: np.ndarray | None = None, stiffness: np.ndarray | None = None) -> None:
        """As :meth:`TissueModel.step`. With ``solver="prefactored"``, no external forces (``forces``
        None and ``external_forces`` the model's own zero load) and no contact stiffness, the step
        touches only the contact region: the prefactored solution, the nodes near the contact
        written (finite-checked, finite-difference velocities), the rest recovered when read."""
        if (self.solver != "prefactored" or self._elastic or forces is not None or stiffness is not None
                or self.external_forces is not self._ext_zero or self._seed_all):
            return super().step(dt, forces, stiffness)
        if not (isinstance(dt, (float, int, np.floating)) and math.isfinite(dt) and dt > 0):   # once per step:
            validate.positive(dt, "dt", unit="s", fix="the default is 1e-3 s")              # the check inline
        pc = self._prefactored_solver()
        self._last_dt = float(dt)
        self._xversion += 1
        prev = self._touched[:self._n_touched]
        self.velocities[prev] = 0.0
        contact = self._contacts(pc)
        near = pc._near_nodes(contact) if len(contact) else pc.near
        before = self._x[near]
        before_stamp = self._xstamp[near]
        nodes, settled = pc.solve(contact)
        if not settled:  # the rigid links did not settle: the active-set all-node solve
            self.prefactored_fallbacks = getattr(self, "prefactored_fallbacks", 0) + 1
            self._lazy = False
            self.static_solve(self.external_forces, self._zero_kc)
            nodes = np.flatnonzero(~self.fixed)
            self.velocities[nodes] = 0.0
        else:
            from surgsim_envs.tissue.layered_prefactored_kernels import fd_velocities

            self._lazy = True
            fd_velocities(near, before, before_stamp, self._xversion, self._x, self.velocities, 1.0 / float(dt))
            nodes = near
        self._touched[:len(nodes)] = nodes
        self._n_touched = len(nodes)
        self.last_updates, self.last_sweeps, self.last_active = len(nodes), 1, len(nodes)
        self.unconverged = 0
        self._moved_fixed = np.zeros(0, dtype=np.int64)
        self._n_queue = 0
        if self._ief_nonzero:
            self.integrated_external_forces[:] = 0.0
            self._ief_nonzero = False
        self.time += float(dt)
        self.steps += 1
        if not pc.finite:   # every written node is checked; the slab sweep covers all of them
            self._lazy = False
            self.guard.fail(self, float(dt), f"non-finite positions at t={self.time:.4g} s")

    def _prefactored_solve(self, ext: np.ndarray, kc: np.ndarray, dt: float | None) -> bool:
        """The "prefactored" solver's step from :meth:`solve` (everything written); False if it
        does not apply (external forces or contact stiffness)."""
        if self._seed_all or np.any(kc > 0) or np.any(ext != 0.0):
            return False
        pc = self._prefactored_solver()
        self._xversion += 1
        prev_touched = self._touched[:self._n_touched].copy()
        self.velocities[prev_touched] = 0.0
        before = self._x.copy()
        _, settled = pc.solve(self._contacts(pc), full=True)
        self._lazy = False
        if not settled:  # the rigid links did not settle: the active-set all-node solve
            self.prefactored_fallbacks = getattr(self, "prefactored_fallbacks", 0) + 1
            self.static_solve(ext, kc)
        nodes = np.flatnonzero(~self.fixed)
        if dt is not None and dt > 0:  # finite-difference velocities
            self.velocities[nodes] = (self._x[nodes] - before[nodes]) / dt
        self._touched[:len(nodes)] = nodes
        self._n_touched = len(nodes)
        self.last_updates, self.last_sweeps, self.last_active = len(nodes), 1, len(nodes)
        self.unconverged = 0
        if self._ief_nonzero:  # no external load on this path
            self.integrated_external_forces[:] = 0.0
            self._ief_nonzero = False
        self._moved_fixed = np.zeros(0, dtype=np.int64)
        self._n_queue = 0
        self.external_forces = self._ext_zero
        return True

    def solve(self, forces=None, stiffness=None, *, dt: float | None = None, all_nodes: bool = False,
              max_updates: int | None = None) -> int:
        """Relax to the local static equilibrium under ``forces`` (N,3) N with implicit contact
        ``stiffness`` (N,) N/m; returns the number of node updates. ``all_nodes`` starts from every
        free node (the all-node solution); ``dt`` only sets the finite-difference velocities."""
        n = self.n_nodes
        ext = self.external_forces if forces is None else np.ascontiguousarray(forces, dtype=np.float64)
        kc = self._zero_kc if stiffness is None else np.ascontiguousarray(stiffness, dtype=np.float64)
        if kc.shape != (n,) or np.any(kc < 0):
            raise ConfigError(f"layered: stiffness must be (N,) >= 0 N/m, got shape {kc.shape}")
        if self._elastic:
            return self._elastic_solve(ext, kc, dt)
        if self.solver == "prefactored" and not all_nodes and self._prefactored_solve(ext, kc, dt):
            return self.last_updates
        step_id = self.steps
        self._qid += 1
        qid = self._qid
        # carried-over active nodes keep their places; loads and moved Dirichlet nodes add more
        self._loaded_prev, self._loaded = self._loaded, self._loaded_prev
        n_prev = self._n_loaded
        n_loaded, nq = kern.seed_loaded(ext, kc, self.fixed, self._loaded_prev, n_prev, self._loaded, self._queue,
                                        self._n_queue, self._qstamp, qid)
        if self._moved_fixed.size:
            nq = kern.seed_neighbours(self._moved_fixed, self.nbr, self.fixed, self._queue, nq, self._qstamp, qid)
            self._moved_fixed = np.zeros(0, dtype=np.int64)
        if all_nodes or self._seed_all:
            free = np.flatnonzero(~self.fixed)
            self._queue[:len(free)] = free
            nq = len(free)
            self._qstamp[free] = qid
            self._seed_all = False
        # forget the previous step's finite-difference velocities
        prev_touched = self._touched[:self._n_touched].copy()
        self.velocities[prev_touched] = 0.0
        budget = self.max_updates if max_updates is None else int(max_updates)
        n_touched, nq, updates, qid, sweeps = kern.relax(
            self.positions, self.rest_positions, self.nbr, self.kk, self.lmin, self.fixed, ext, kc, self.push,
            self._xs, self._tstamp, step_id, self._touched, 0, self._queue, nq, self._nxt, self._qstamp, qid,
            self.f_tol, self.x_tol, budget, self.omega)
        self._qid = qid
        self._n_queue = nq
        self._n_touched = n_touched
        self._n_loaded = n_loaded
        self.last_updates, self.last_sweeps, self.last_active, self.unconverged = updates, sweeps, n_touched, nq
        touched = self._touched[:n_touched]
        if dt is not None and dt > 0:
            self.velocities[touched] = (self.positions[touched] - self._xs[touched]) / dt
        self._ief_nonzero = True
        # external force actually integrated: g + kc (xs - x) on loaded nodes
        prev_loaded = self._loaded_prev[:n_prev]
        self.integrated_external_forces[prev_loaded] = 0.0
        ld = self._loaded[:n_loaded]
        if len(ld):
            xs = np.where((self._tstamp[ld] == step_id)[:, None], self._xs[ld], self.positions[ld])
            self.integrated_external_forces[ld] = ext[ld] + kc[ld, None] * (xs - self.positions[ld])
        self.external_forces = ext
        return updates

    def static_solve(self, forces=None, stiffness=None, method: str = "direct", max_sweeps: int = 400,
                     **kwargs) -> np.ndarray:
        """Equilibrium positions (N,3) m under ``forces`` (N,3) N (and implicit ``stiffness`` (N,) N/m)
        with every free node active: the all-node solution.

        method "direct": the springs' linear system (eq. 2.8 for all nodes at once) solved by sparse
        LU, springs at their extreme length held as rigid links by an active-set iteration, their
        forces stored as the accumulated pushes (:mod:`surgsim_envs.tissue.layered_block`);
        ``self.unconverged`` is N if the active set did not settle, else 0. "local": the local
        iteration alone from the current state (slow for large volumes: at most ``max_sweeps`` x N
        node updates; ``self.unconverged`` counts the nodes still active after).
        """
        if method not in ("direct", "local"):
            raise ConfigError(f"layered: static_solve method must be 'direct' or 'local', got {method!r}")
        n = self.n_nodes
        ext = self.external_forces if forces is None else np.ascontiguousarray(forces, dtype=np.float64)
        kc = self._zero_kc if stiffness is None else np.ascontiguousarray(stiffness, dtype=np.float64)
        if method == "direct" and self._elastic:
            fixed = np.flatnonzero(self.fixed)
            self.positions[fixed] = self.fixed_targets[fixed]
            self._elastic_solve(ext, kc, None)
            return self.positions.copy()
        if method == "direct":
            from surgsim_envs.tissue.layered_block import BlockSolver

            fixed = np.flatnonzero(self.fixed)
            self.positions[fixed] = self.fixed_targets[fixed]
            self.push[:] = 0.0
            solver = BlockSolver(self, np.flatnonzero(~self.fixed))
            settled = solver.solve(ext, kc, self.positions.copy())
            self.unconverged = 0 if settled else n
            self.last_active_set_iterations = solver.last_iterations
            self._n_queue = 0
            self._moved_fixed = np.zeros(0, dtype=np.int64)
            self.external_forces = ext
            return self.positions.copy()
        self.solve(ext, kc, all_nodes=True, max_updates=int(max_sweeps) * n)
        self._n_queue = 0  # a static solve leaves no work for the next step
        return self.positions.copy()

    def _laplacian(self):
        """Scalar spring stiffness diag(sum K) - K (N x N, N/m), cached until the springs change."""
        lap = getattr(self, "_lap_cache", None)
        if lap is None:
            from surgsim_envs.tissue.layered_block import laplacian

            lap = self._lap_cache = laplacian(self.nbr, self.kk)
        return lap

    def _clamp_into_nbb(self) -> None:
        """Move nodes that left their neighbouring bounding box back to its edge (in place)."""
        x = self.positions
        for _ in range(50):
            bad = 0
            for d in (1, 3, 5):
                a = d // 2
                j = self.nbr[:, d]
                ok = np.flatnonzero(j >= 0)
                gap = x[j[ok], a] - x[ok, a] - self.lmin[ok, d]
                viol = gap < 0
                if viol.any():
                    bad += int(viol.sum())
                    ii, jj = ok[viol], j[ok][viol]
                    mid = 0.5 * (x[ii, a] + x[jj, a])
                    half = 0.5 * self.lmin[ii, d]
                    fi, fj = self.fixed[ii], self.fixed[jj]
                    x[ii[~fi], a] = np.where(fj[~fi], x[jj[~fi], a] - 2 * half[~fi], mid[~fi] - half[~fi])
                    x[jj[~fj], a] = np.where(fi[~fj], x[ii[~fj], a] + 2 * half[~fj], mid[~fj] + half[~fj])
            if not bad:
                break

    # ------------------------------------------------------------------------------------------
    def internal_forces(self) -> np.ndarray:
        """(N,3) N spring forces on every node, with forces accumulated through rigid springs."""
        if self._elastic:
            from surgsim_envs.tissue.layered_elastic import elastic_forces

            return elastic_forces(self, np.arange(self.n_nodes))
        out = np.zeros((self.n_nodes, 3))
        kern.spring_forces(self.positions, self.rest_positions, self.nbr, self.kk, self.push,
                           np.arange(self.n_nodes, dtype=np.int64), out)
        return out

    def contact_force(self, nodes) -> np.ndarray:
        """(3,) N, the force the tissue exerts on a tool that holds ``nodes`` (the contact mass points):
        the sum of their spring forces, accumulated through rigid springs (eqs. 2.4-2.5)."""
        idx = self._as_indices(nodes, "contact nodes")
        if self._elastic:
            from surgsim_envs.tissue.layered_elastic import elastic_forces

            return elastic_forces(self, idx).sum(axis=0)
        out = np.zeros((len(idx), 3))
        x = self._x
        if self._lazy:
            from surgsim_envs.tissue.layered_prefactored_kernels import all_fresh

            if not all_fresh(idx, self.nbr, self._xstamp, self._xversion, self._prefactored_solver().local, self.fixed):
                x = self.positions
        kern.spring_forces(x, self.rest_positions, self.nbr, self.kk, self.push, idx, out)
        return out.sum(axis=0)

    def elastic_energy(self) -> float:
        if self._elastic:
            u = (self.positions - self.rest_positions).ravel()
            return float(0.5 * u @ (self._elastic_k @ u))
        return float(kern.elastic_energy(self.positions, self.rest_positions, self.nbr, self.kk))

    def critical_dt(self) -> float:
        return math.inf

    def stable_dt(self) -> float:
        """inf: a static solve per step has no explicit stability limit (contract v2)."""
        return math.inf

    def stiffness_matrix(self, relaxed: bool = True):
        """Sparse 3N x 3N ``-df/dx`` of the springs (node-major dofs), without the NBB constraints."""
        import scipy.sparse as sp

        if self._elastic:
            return self._elastic_k.copy()
        n = self.n_nodes
        i_idx, d_idx = np.nonzero(self.nbr >= 0)
        j = self.nbr[i_idx, d_idx]
        k = self.kk[i_idx, d_idx]
        lap = sp.coo_matrix((-k, (i_idx, j)), shape=(n, n)).tocsr()
        lap = lap + sp.diags(self.kk.sum(axis=1))
        return sp.kron(lap, sp.identity(3), format="csr")

    # ------------------------------------------------------------------------------------------
    # contract v2 readouts
    def node_fields(self) -> dict[str, np.ndarray]:
        """displacement (m), stress (Pa, sqrt(3) G_L |grad u|, a von Mises measure of the shear the
        springs carry), active (1 on nodes updated in the last step), layer (region index),
        material (index into ``volume.material_names``)."""
        u = self.positions - self.rest_positions
        disp = np.linalg.norm(u, axis=1)
        g2 = np.zeros(self.n_nodes)
        gl = np.zeros(self.n_nodes)
        cnt = np.zeros(self.n_nodes)
        for d in range(6):
            j = self.nbr[:, d]
            ok = j >= 0
            du = u[j[ok]] - u[ok]
            g2[ok] += np.einsum("ij,ij->i", du, du) / self.rest_lengths[ok, d] ** 2
            gl[ok] += self.kk[ok, d] * self.rest_lengths[ok, d] / np.maximum(self.volume.spring_area[ok, d], 1e-300)
            cnt[ok] += 1
        gl = gl / np.maximum(cnt, 1)
        active = np.zeros(self.n_nodes)
        active[self._touched[:self._n_touched]] = 1.0
        return {"displacement": disp, "stress": math.sqrt(3.0) * gl * np.sqrt(0.5 * g2),
                "active": active, "layer": self.volume.node_labels.astype(np.float64),
                "material": self.volume.node_material.astype(np.float64)}

    def field_names(self) -> list[str]:
        return list(self.node_fields())

    def element_centroids(self) -> np.ndarray:
        """(T,3) m rest centroids of the tets (whose labels are the layers)."""
        return self.rest_positions[self.volume.tets].mean(axis=1)

    def interpenetrations(self) -> int:
        """Number of neighbour pairs whose order along their axis has flipped (0: no layer passed another)."""
        x = self.positions
        bad = 0
        for d in (1, 3, 5):
            j = self.nbr[:, d]
            ok = j >= 0
            a = d // 2
            bad += int(np.count_nonzero(x[j[ok], a] - x[ok, a] <= 0.0))
        return bad

    def link_gaps(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Per axis x, y, z: (gap (K,) m = neighbour distance along the axis minus its extreme length,
        rigid (K,) bool = the link passes force on (eq. 2.5), extreme lengths (K,) m) over the nodes
        with a + neighbour. gap < 0 is a pair pushed past its extreme length; a rigid link sits at 0."""
        x = self.positions
        out = []
        for a in range(3):
            j = self.nbr[:, 2 * a + 1]
            ok = np.flatnonzero(j >= 0)
            lmin = self.lmin[ok, 2 * a + 1]
            out.append((x[j[ok], a] - x[ok, a] - lmin, self.push[ok, 2 * a + 1] > 0, lmin))
        return out

    def describe(self) -> dict:
        out = super().describe()
        out.update({"materials": list(self.volume.material_names), "layers": list(self.volume.layer_names),
                    "rigid_nodes": int(len(self.rigid_nodes)), "max_compression": self.max_compression,
                    "f_tol": self.f_tol, "x_tol": self.x_tol, "stiffness": self.stiffness_form})
        return out


__all__ = ["LayeredModel", "laplace_modulus", "MAX_COMPRESSION", "DIRECTIONS"]
