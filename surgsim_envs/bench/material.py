"""Virtual material tests: spherical indentation, ramp-and-hold relaxation, grasp-and-pull slip.

Every test takes a registered tissue model (name or class), a material (preset name, dict or
:class:`~surgsim_envs.tissue.Material`) and returns plain arrays in SI units (m, N, s), so the
results can be compared with the closed forms of :mod:`surgsim_envs.bench.references`.

* :func:`indent` -- a rigid sphere pressed slowly into a square slab on a rigid base. Quasi-static:
  the model's small-strain stiffness (its linearisation about rest; relaxed for viscoelastic
  models) is condensed onto the top-surface nodes under the indenter, and frictionless contact
  is solved exactly as a linear complementarity problem at every depth (a node touches the
  sphere or is force-free; no penalty parameter). A short dynamic run on the same mesh measures
  the wall time of one physics step (tissue step + contact detection).
* :func:`relax` -- a block between two bonded plates, compressed at constant rate, then held:
  force on the top plate against time, stepped with the model's own integrator.
* :func:`slip` -- three flat jaws squeeze a tissue cylinder, then a soft handle spring pulls it
  along its axis until the grasp slides; the pull, the summed jaw normal force and the pull at
  slip onset, read from how far the contact points slid along the jaws (the rig of
  ``tests/test_grasp_slip.py``, for any model).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.optimize as so
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from surgsim_envs import validate
from surgsim_envs.bench.slip_onset import SLID_SHARE, SLIP_DISTANCE
from surgsim_envs.errors import ConfigError, TissueUnstableError
from surgsim_envs.materials import Material, get_material

DEFAULT_DT = 1e-3  # s


# ----------------------------------------------------------------------------------------------
# helpers
def model_class(model):
    """Registered model class for a name (or the class itself)."""
    from surgsim_envs.tissue import registry
    from surgsim_envs.tissue.base import TissueModel

    if isinstance(model, str):
        return registry.get(model)
    if isinstance(model, type) and issubclass(model, TissueModel):
        return model
    raise ConfigError(f"model must be a registered model name or a TissueModel subclass, got {model!r}")


#: nodes a virtual material test may mesh (a finer mesh takes hours per test)
MAX_TEST_NODES = 1_000_000


def is_explicit(cls, integrator: str | None) -> bool:
    """Whether ``integrator`` of model class ``cls`` has an explicit dt limit, from the contract
    (no integrator-name lists): quasi-static models and "auto" (which switches to the implicit
    member of ``auto_pair`` above the limit) have none, nor has the implicit member itself."""
    integ = integrator or cls.default_integrator or cls.integrators[0]
    if integ == "auto" or "quasi_static" in cls.capabilities:
        return False
    return not (cls.auto_pair is not None and integ == cls.auto_pair[1])


def stable_dt(model, dt: float | None = None) -> float:
    """``dt`` (default 1 ms), reduced to the model's ``stable_dt()`` (DT_SAFETY x critical dt, the
    one safety factor) for explicit integrators."""
    dt = DEFAULT_DT if dt is None else float(dt)
    if is_explicit(type(model), model.integrator):
        limit = float(model.stable_dt())
        if math.isfinite(limit) and limit > 0:
            dt = min(dt, limit)
    return dt


def linear_stiffness(model) -> sp.csr_matrix:
    """Small-strain stiffness ``-df/dx`` (3N x 3N, N/m) of ``model`` about its current state.

    Uses ``model.stiffness_matrix`` (a method taking ``relaxed=True`` for viscoelastic models, or a
    sparse attribute); otherwise builds it by central differences of ``internal_forces`` (only for
    models up to 3,000 nodes).
    """
    sm = getattr(model, "stiffness_matrix", None)
    if callable(sm):
        try:
            k = sm(relaxed=True)
        except TypeError:
            k = sm()
        return sp.csr_matrix(k)
    if sm is not None and sp.issparse(sm):
        return sm.tocsr()
    n = model.n_nodes
    if n > 3000:
        raise ConfigError(f"model '{model.name}' exposes no stiffness_matrix and has {n} nodes; finite-difference "
                          "stiffness is limited to 3,000 nodes (coarsen the mesh or add stiffness_matrix)")
    x0 = model.positions.copy()
    h = 1e-7 * float(np.ptp(x0, axis=0).max())
    cols = []
    for j in range(3 * n):
        model.positions = x0.copy()
        model.positions.reshape(-1)[j] += h
        fp = model.internal_forces().ravel()
        model.positions = x0.copy()
        model.positions.reshape(-1)[j] -= h
        fm = model.internal_forces().ravel()
        cols.append(sp.csc_matrix(-(fp - fm)[:, None] / (2 * h)))
    model.positions = x0
    k = sp.hstack(cols).tocsr()
    return (0.5 * (k + k.T)).tocsr()


def _build(cls, volume, material, opts: dict[str, Any], fixed=None):
    opts = dict(opts)
    try:
        return cls(volume, material, fixed=fixed, **opts)
    except TypeError as exc:
        raise ConfigError(f"model '{cls.name}' rejected options {sorted(opts)}: {exc}") from None


# ----------------------------------------------------------------------------------------------
# Indentation
@dataclass
class IndentResult:
    """Indentation curve: ``depth`` (m), ``force`` (N) on the sphere, ``nodes`` of the simulated mesh,
    ``us_per_step`` (wall time of one dynamic physics step, microseconds) at ``dt`` (s)."""

    depth: np.ndarray
    force: np.ndarray
    nodes: int
    us_per_step: float
    dt: float
    model: str = ""
    integrator: str = ""
    spacing: float = 0.0
    info: dict = field(default_factory=dict)
    #: (positions (N,3) m, top-surface triangles) at the deepest depth, for shape errors (not serialised)
    top_surface: tuple | None = field(default=None, repr=False, compare=False)

    @property
    def us_per_ms(self) -> float:
        """Compute cost per simulated millisecond (us / ms)."""
        return self.us_per_step * 1e-3 / self.dt

    def as_dict(self) -> dict:
        out = asdict(self)
        out.pop("top_surface", None)
        out["depth"] = [float(v) for v in self.depth]
        out["force"] = [float(v) for v in self.force]
        out["us_per_ms"] = self.us_per_ms
        return out


def _solve_lcp(c: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Contact pressures p >= 0 (N) with w = C p + g >= 0, p.w = 0 (C SPD compliance, m/N).

    Equivalent to min 0.5 p'Cp + g'p, p >= 0; solved as NNLS on the Cholesky factor."""
    if not np.any(g < 0):
        return np.zeros_like(g)
    low = sla.cholesky(c, lower=True)
    rhs = -sla.solve_triangular(low, g, lower=True)
    p, _ = so.nnls(low.T, rhs, maxiter=50 * len(g))
    return p


def indent(model, material="liver", *, indenter_radius: float = 0.005, depth: float = 0.003,
           thickness: float = 0.03, width: float | None = None, spacing: float | None = None, bonded: bool = True,
           n_depths: int = 12, grading: float = 1.3, max_cell: float | None = None, quarter: bool = True,
           dt: float | None = None, time_steps: int = 20, progress=None, **opts) -> IndentResult:
    """Press a rigid sphere (``indenter_radius`` m) up to ``depth`` (m) into a square slab
    (``width`` m, default 4 x ``thickness``; ``thickness`` m) lying on a rigid base.

    bonded: bottom nodes fixed in all directions (else in z only: a frictionless base).
    spacing: mesh spacing (m) under the indenter, default min(sqrt(R d)/4, thickness/6); cells grow
        by ``grading`` per cell away from the contact zone, up to ``max_cell`` (default 8 x spacing).
    quarter: simulate a quarter slab with symmetry conditions (exact for a centred sphere; 4x fewer
        nodes); the force is that of the whole slab.
    n_depths: depths sampled uniformly in (0, depth].
    dt, time_steps: the timed dynamic run (dt default 1 ms, reduced to the model's stable_dt() for
        explicit integrators); ``time_steps=0`` skips it (us_per_step = nan).
    progress: optional ``progress(label)``, called after each of :func:`indent_stages` stages
        (the compliance solve, each depth, the timed run) for a progress bar.
    **opts: model options (e.g. integrator="implicit").

    Returns an :class:`IndentResult` (depth m, force N, nodes, us_per_step).
    """
    from surgsim_envs.bench.indent_mesh import graded_slab

    cls = model_class(model)
    mat = get_material(material)
    validate.positives(fix="give a positive number (SI units)", indenter_radius=indenter_radius, depth=depth, thickness=thickness)
    R = float(indenter_radius)
    if depth >= min(R, thickness):
        raise ConfigError(f"depth {depth} m must be smaller than the indenter radius ({R} m) and the thickness "
                          f"({thickness} m)")
    a_max = math.sqrt(R * depth)
    width = 4.0 * thickness if width is None else width
    spacing = min(a_max / 4.0, thickness / 6.0) if spacing is None else spacing
    validate.positives(fix="give a positive number (SI units)", width=width, spacing=spacing, grading=grading)
    if width < 4.0 * a_max:
        raise ConfigError(f"width {width} m is too small for a contact radius of {a_max:.3g} m; use >= {4 * a_max:.3g} m")
    validate.integer(n_depths, "n_depths", lo=1, hi=10_000, fix="the number of depths of the curve, e.g. 12")
    zone = min(0.999 * R, 1.6 * a_max + 2.0 * spacing)
    if "surface_only" in getattr(cls, "capabilities", ()):
        quarter = False      # a surface model would take the quarter mesh's symmetry cuts for free surface
    vol = graded_slab(width, thickness, spacing, zone + 2.0 * spacing, grading=grading, max_cell=max_cell,
                      quarter=quarter)
    X = vol.nodes
    bottom = np.isclose(X[:, 2], -thickness)
    tissue = _build(cls, vol, mat, opts, fixed=bottom)

    # constrained dofs: base, symmetry planes (and rigid modes of an unbonded full slab)
    n = vol.n_nodes
    cons = np.zeros((n, 3), dtype=bool)
    cons[bottom, 2] = True
    if bonded:
        cons[bottom] = True
    if quarter:
        cons[np.isclose(X[:, 0], 0.0), 0] = True
        cons[np.isclose(X[:, 1], 0.0), 1] = True
    elif not bonded:
        centre = np.flatnonzero(bottom & np.isclose(X[:, 0], 0.0) & np.isclose(X[:, 1], 0.0))
        side = np.flatnonzero(bottom & np.isclose(X[:, 1], 0.0) & (X[:, 0] > 0))
        cons[centre, :2] = True
        cons[side[:1], 1] = True
    r = np.hypot(X[:, 0], X[:, 1])
    cand = np.flatnonzero(np.isclose(X[:, 2], 0.0) & (r < zone))
    sol = None
    if callable(getattr(tissue, "contact_compliance", None)):
        comp = tissue.contact_compliance(cand, axis=2)  # models whose static response is not a stiffness matrix
    else:
        K = linear_stiffness(tissue)
        free = ~cons.ravel()
        kff = K[free][:, free].tocsc()
        try:
            lu = spla.splu(kff)
        except RuntimeError as exc:
            raise ConfigError(f"indent: singular stiffness for model '{cls.name}' ({exc})") from None
        index = -np.ones(3 * n, dtype=np.int64)
        index[free] = np.arange(int(free.sum()))
        zdofs = index[3 * cand + 2]
        rhs = np.zeros((kff.shape[0], len(cand)))
        rhs[zdofs, np.arange(len(cand))] = 1.0
        sol = lu.solve(rhs)
        comp = sol[zdofs]                               # m/N: z displacement per unit upward z force
    comp = 0.5 * (comp + comp.T)
    if progress is not None:
        progress("compliance of the contact zone")
    gap0 = R - np.sqrt(R * R - r[cand] ** 2)            # sphere surface height above its lowest point
    depths = np.linspace(depth / n_depths, depth, n_depths)
    forces = np.empty(n_depths)
    p = np.zeros(len(cand))
    for k, d in enumerate(depths):
        p = _solve_lcp(comp, gap0 - d)                  # gap g = -d + gap0 (u_z <= g)
        forces[k] = p.sum() * (4.0 if quarter else 1.0)
        if progress is not None:
            progress(f"depth {d * 1e3:.3g} mm")

    top_surface = None                                 # deformed top surface at the deepest depth
    if sol is not None:                                # (models solved through a stiffness matrix)
        u = np.zeros(3 * n)
        u[free] = -(sol @ p)
        top = vol.surface[np.all(np.isclose(X[vol.surface, 2], 0.0), axis=1)]
        top_surface = (X + u.reshape(-1, 3), top)
    us, dt_used = math.nan, math.nan
    if time_steps:
        load = np.zeros((n, 3))
        load[cand, 2] = -0.1 * p                       # a gentle load: timing, not a dynamic test
        try:
            us, dt_used = _time_steps(tissue, load, R, depth, dt, int(time_steps))
        except TissueUnstableError as exc:          # report it; the force curve is still valid
            us, dt_used = math.nan, exc.dt
        if progress is not None:
            progress("timed steps")
    return IndentResult(depths, forces, n, us, dt_used, cls.name, tissue.integrator, float(spacing),
                        {"bonded": bool(bonded), "quarter": bool(quarter), "thickness": float(thickness),
                         "width": float(width), "radius": R, "young": mat.young, "poisson": mat.poisson,
                         "contact_nodes": int(np.count_nonzero(p)), "candidate_nodes": int(len(cand))},
                        top_surface=top_surface)


def indent_stages(n_depths: int = 12, time_steps: int = 20) -> int:
    """How many times :func:`indent` calls its ``progress`` callback."""
    return 1 + int(n_depths) + (1 if time_steps else 0)


def _time_steps(tissue, load: np.ndarray, radius: float, depth: float, dt: float | None, steps: int):
    """Median wall time (us) of one physics step: contact detection on the surface nodes plus the
    tissue step under the indentation load. Returns (us_per_step, dt)."""
    from surgsim_envs.contact import SPHERE, ContactModel, ContactParams

    dt = stable_dt(tissue, dt)
    cm = ContactModel(tissue.n_nodes, tissue.surface_nodes, [0.0], ContactParams(stiffness=200.0))
    kind, tool = np.array([SPHERE]), np.array([0])
    size = np.array([[radius, 0.0, 0.0]])
    pos = np.array([[0.0, 0.0, radius - depth]])
    mat = np.eye(3).reshape(1, 9)
    vel, com = np.zeros((1, 6)), np.zeros((1, 3))
    times = []
    for i in range(steps + 3):
        t0 = time.perf_counter()
        cm.compute(tissue.positions, tissue.velocities, kind, tool, size, pos, mat, vel, com, dt)
        tissue.step(dt, load)
        if i >= 3:                                     # the first steps compile numba kernels
            times.append(time.perf_counter() - t0)
    return float(np.median(times) * 1e6), float(dt)


# ----------------------------------------------------------------------------------------------
# Ramp-and-hold relaxation
@dataclass
class RelaxResult:
    """Compression force on the top plate (N, positive in compression) against ``time`` (s)."""

    time: np.ndarray
    force: np.ndarray
    nodes: int
    area: float
    height: float
    strain: float
    ramp_time: float
    dt: float
    model: str = ""
    integrator: str = ""

    def as_dict(self) -> dict:
        return {"time": [float(v) for v in self.time], "force": [float(v) for v in self.force],
                "nodes": self.nodes, "area": self.area, "height": self.height, "strain": self.strain,
                "ramp_time": self.ramp_time, "dt": self.dt, "model": self.model, "integrator": self.integrator}


def relax(model, material="liver", *, strain: float = 0.05, ramp_time: float = 0.2, hold_time: float = 3.0,
          size=(0.02, 0.02, 0.02), spacing: float = 0.005, dt: float | None = None, samples: int = 200,
          **opts) -> RelaxResult:
    """Ramp-and-hold compression of a block (``size`` m) between bonded rigid plates.

    The top plate moves down by ``strain`` x height at constant speed over ``ramp_time`` (s) and is
    then held for ``hold_time`` (s). The force (N) is the sum of the z reactions on the top nodes
    (``internal_forces`` there). The model's implicit integrator is used when it has one (override
    with ``integrator=...``); ``dt`` defaults to 1 ms (0.8 x critical dt if explicit). About
    ``samples`` points are returned.
    """
    from surgsim_envs.geometry import box_volume

    cls = model_class(model)
    mat = get_material(material)
    validate.positives(fix="give a positive number (SI units)", strain=strain, ramp_time=ramp_time, hold_time=hold_time, spacing=spacing, samples=samples)
    if strain >= 0.5:
        raise ConfigError(f"strain {strain} is too large for a relaxation test; use 0.01-0.2")
    if "integrator" not in opts and "implicit" in cls.integrators:
        opts = {**opts, "integrator": "implicit"}
    validate.grid_nodes(size, spacing, "relax", hi=MAX_TEST_NODES)
    vol = box_volume(tuple(size), spacing, center=(0.0, 0.0, size[2] / 2.0), name="relax_block")
    z = vol.nodes[:, 2]
    bottom, top = np.isclose(z, 0.0), np.isclose(z, z.max())
    tissue = _build(cls, vol, mat, opts, fixed=bottom | top)
    dt = stable_dt(tissue, dt)
    h = float(size[2])
    n_steps = (ramp_time + hold_time) / dt
    if n_steps > validate.MAX_PHYSICS_STEPS:
        raise ConfigError(f"relax: ramp_time + hold_time = {ramp_time + hold_time:g} s at dt = {dt:.3g} s is "
                          f"{n_steps:.3g} steps, above the {validate.MAX_PHYSICS_STEPS:,} a test may run (hours of "
                          f"CPU); shorten hold_time to at most {validate.MAX_PHYSICS_STEPS * dt - ramp_time:.4g} s")
    n_steps = int(round(n_steps))
    every = max(1, n_steps // int(samples))
    top_idx = np.flatnonzero(top)
    targets = tissue.rest_positions[top_idx].copy()
    times, forces = [0.0], [0.0]
    for i in range(1, n_steps + 1):
        t = i * dt
        targets[:, 2] = h - strain * h * min(t / ramp_time, 1.0)
        tissue.set_fixed(top_idx, targets)
        tissue.step(dt)
        if i % every == 0 or i == n_steps:
            times.append(t)
            forces.append(float(tissue.internal_forces()[top_idx, 2].sum()))
    return RelaxResult(np.array(times), np.array(forces), vol.n_nodes, float(size[0] * size[1]), h, float(strain),
                       float(ramp_time), float(dt), cls.name, tissue.integrator)


# ----------------------------------------------------------------------------------------------
# Grasp and pull
@dataclass
class SlipResult:
    """Grasp-and-pull record from the start of the pull: ``time`` (s), ``pull`` (N), ``normal_sum``
    (N, summed jaw normal force), ``slide`` (m, axial motion of the tissue's centre of mass relative
    to the jaws); ``slip_onset_pull`` (N): pull at gross slip (see :func:`slip`'s ``onset``);
    ``slip_onset_normal`` (N) the jaws' normal force at that instant; ``held_pull`` (N) the largest
    pull up to the onset, the most the grasp held, and ``held_normal`` (N) the jaws' normal force at
    the instant it was reached (Coulomb bounds the held force by mu_static times it);
    ``normal_start`` (N) the jaws' normal force when the pull began. ``node_slip`` (K, S) m: each
    surface node's slip along the jaws (:class:`~surgsim_envs.bench.slip_onset.AnchorSlip`) and
    ``node_normal`` (K, S) N its normal force, every 0.05 s of pull (``node_slip_time``, s), and
    ``node_z`` (S,) m the surface nodes' axial rest coordinates: where on the grip the slip starts."""

    time: np.ndarray
    pull: np.ndarray
    normal_sum: np.ndarray
    slide: np.ndarray
    slip_onset_pull: float | None
    slip_onset_normal: float | None
    mu: float
    nodes: int
    model: str = ""
    #: share of the contact points sliding (at the Coulomb cap) and axial speed (m/s) of the contact
    #: patch relative to the jaws, per sample (see :mod:`surgsim_envs.bench.slip_onset`)
    slip_share: np.ndarray = field(default_factory=lambda: np.zeros(0))
    patch_speed: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: |sum of friction forces| / (mu * sum of normal forces): 1 when every contact is at its cap
    mobilised: np.ndarray = field(default_factory=lambda: np.zeros(0))
    onset: str = "slide"
    #: static friction coefficient of the jaws (= mu unless set; the onset reference is mu_static * N)
    mu_static: float = math.nan
    #: share of the jaws' normal force on contact points that have slid ``slip_distance`` since the
    #: pull began, per sample (the onset criterion, :mod:`surgsim_envs.bench.slip_onset`)
    slid_share: np.ndarray = field(default_factory=lambda: np.zeros(0))
    held_pull: float | None = None
    held_normal: float | None = None
    normal_start: float | None = None
    node_slip: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    node_normal: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    node_slip_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    node_z: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def as_dict(self) -> dict:
        return {"pull": [float(v) for v in self.pull], "normal_sum": [float(v) for v in self.normal_sum],
                "slip_onset_pull": self.slip_onset_pull, "slip_onset_normal": self.slip_onset_normal,
                "time": [float(v) for v in self.time], "slide": [float(v) for v in self.slide],
                "slip_share": [float(v) for v in self.slip_share], "patch_speed": [float(v) for v in self.patch_speed],
                "mobilised": [float(v) for v in self.mobilised], "slid_share": [float(v) for v in self.slid_share],
                "held_pull": self.held_pull, "held_normal": self.held_normal, "normal_start": self.normal_start,
                "onset": self.onset, "mu": self.mu, "mu_static": self.mu_static, "nodes": self.nodes,
                "model": self.model}


#: s, the shortest pull :func:`slip` records, and the longest it ramps before it reports that the
#: grasp never slid
PULL_TIME, MAX_PULL_TIME = 0.6, 5.0
#: s of pull recorded after the onset (the sliding that follows it)
AFTER_ONSET = 0.1

SLIP_MATERIAL = Material(young=20_000.0, poisson=0.45, density=1000.0, damping=10.0, name="gel")


def grasp_cylinder(radius: float, length: float, spacing: float):
    """Tet volume of a tissue cylinder (axis z, centred at the origin), lattice + surface snapping."""
    import trimesh

    from surgsim_envs.geometry.lattice import lattice_volume

    return lattice_volume(trimesh.creation.cylinder(radius=radius, height=length, sections=48), spacing)


def _end_clamp(tissue, radius: float, spacing: float) -> np.ndarray:
    """Indices of the nodes a clamp holds on the tissue cylinder's far (+z) end face: within a
    quarter spacing of the face and ``radius - 1.5 spacing`` of the axis, clear of the jaws."""
    x = tissue.rest_positions
    on_face = x[:, 2] >= x[:, 2].max() - 0.25 * spacing
    inside = np.hypot(x[:, 0], x[:, 1]) <= radius - 1.5 * spacing
    idx = np.flatnonzero(on_face & inside)
    if len(idx) < 3:
        raise ConfigError(f"slip(handle='clamp'): only {len(idx)} end-face node(s) lie clear of the jaws "
                          f"(radius {radius} m, spacing {spacing} m); use a finer spacing or handle='spring'")
    return idx


def _jaw_frames():
    ang = np.deg2rad([90.0, 210.0, 330.0])
    er = np.stack([np.cos(ang), np.sin(ang), np.zeros(3)], axis=1)
    et = np.stack([-np.sin(ang), np.cos(ang), np.zeros(3)], axis=1)
    ez = np.tile([0.0, 0.0, 1.0], (3, 1))
    mats = np.stack([np.stack([er[k], et[k], ez[k]], axis=1).ravel() for k in range(3)])
    return er, mats


def slip(model, material=None, *, mu: float = 0.6, radius: float = 0.008, length: float = 0.04,
         spacing: float = 0.003, squeeze: float = 0.0005, dt: float | None = None, contact_stiffness: float = 60.0,
         contact_damping: float = 0.02, handle_stiffness: float = 100.0, handle_speed: float = 0.01,
         close_time: float = 0.15, settle_time: float = 0.1, pull_time: float = PULL_TIME, onset_slide: float = 2.5e-3,
         volume=None, onset: str = "contact", mu_static: float | None = None, handle: str = "auto",
         max_pull_time: float = MAX_PULL_TIME, after_onset: float = AFTER_ONSET, slip_distance: float = SLIP_DISTANCE,
         slid_share: float = SLID_SHARE, progress=None, **opts) -> SlipResult:
    """Three flat jaws (120 degrees apart, longer than the tissue) close radially by ``squeeze`` (m)
    on a tissue cylinder (``radius``, ``length`` m) over ``close_time`` s, hold for ``settle_time`` s,
    then a handle spring (``handle_stiffness`` N/m, far end moving at ``handle_speed`` m/s) pulls the
    tissue along its axis (as a body force spread by mass) for at least ``pull_time`` s.

    Coulomb friction ``mu`` on the jaws (kinetic; ``mu_static`` >= mu the static coefficient, None =
    mu); penalty contact ``contact_stiffness`` N/m per node. Gross slip: ``onset="contact"``
    (default) is the first sample at which the contact points that have slid ``slip_distance`` (m)
    along the jaws carry ``slid_share`` of the normal force (:mod:`surgsim_envs.bench.slip_onset`,
    read from the friction anchors, not from the friction force); ``onset="slide"`` when the
    tissue's centre of mass has moved ``onset_slide`` m relative to the jaws (tissue stretch
    included; it lands on a stick-slip dip at low mu).

    The pull goes on past ``pull_time`` until the grasp slides (and ``after_onset`` s more, so that
    the record shows the sliding), up to ``max_pull_time`` s of pull; a grasp that has not slid by
    then, or that holds a pull above twice mu_static times the jaws' normal force (no friction grip
    can), raises :class:`ConfigError` naming the largest pull reached. ``progress(t, pull,
    mu_static_times_normal)`` (s, N, N), if given, is called every 0.05 s of pull.
    ``material`` defaults to a 20 kPa gel. ``tests/test_grasp_slip.py`` asserts the Coulomb behaviour of this rig.

    ``handle``: ``"spring"`` pulls through the handle spring as a body force spread by mass (a body
    with inertia); ``"clamp"`` clamps the centre of the far end face (nodes within ``radius - 1.5
    spacing`` of the axis) and slides the jaws the other way at ``handle_speed`` (displacement
    control, as a pull-out test machine does, in the clamp's frame so that the supports never
    move); the pull is the clamp's reaction, slide and patch speed are taken relative to the jaws. A quasi-static model has no inertia, so
    a free body held only by friction has no equilibrium once it slips and its solver needs
    supports: ``"auto"`` (default) takes ``"clamp"`` for models with the ``quasi_static``
    capability and ``"spring"`` otherwise. ``dt`` (s) defaults to 5e-5, and to 5e-4 for a
    quasi-static model, whose steps are equilibria, so that ``dt`` only sets the sampling.
    """
    from surgsim_envs.bench.slip_onset import AnchorSlip
    from surgsim_envs.contact import BOX, ContactModel, ContactParams

    cls = model_class(model)
    mat = SLIP_MATERIAL if material is None else get_material(material)
    if not (isinstance(mu, (int, float, np.floating)) and math.isfinite(mu) and mu >= 0):
        raise ConfigError(f"mu must be a friction coefficient >= 0, got {mu!r}")
    mu_s = float(mu) if mu_static is None else mu_static
    if not (isinstance(mu_s, (int, float, np.floating)) and math.isfinite(mu_s) and mu_s >= mu):
        raise ConfigError(f"mu_static must be a static friction coefficient >= mu = {mu!r} (or None = mu), "
                          f"got {mu_static!r}")
    quasi_static = cls.has("quasi_static")
    if dt is None:
        dt = 5e-4 if quasi_static else 5e-5
    validate.positives(fix="give a positive number (SI units)", radius=radius, length=length, spacing=spacing, squeeze=squeeze, dt=dt, close_time=close_time,
              settle_time=settle_time, pull_time=pull_time, handle_stiffness=handle_stiffness,
              handle_speed=handle_speed, onset_slide=onset_slide, slip_distance=slip_distance)
    if not (isinstance(max_pull_time, (int, float)) and max_pull_time >= pull_time):
        raise ConfigError(f"max_pull_time must be >= pull_time = {pull_time} s (the ramp only extends), "
                          f"got {max_pull_time!r}")
    if not (isinstance(after_onset, (int, float)) and after_onset >= 0):
        raise ConfigError(f"after_onset must be >= 0 s of pull recorded after the onset, got {after_onset!r}")
    if not (isinstance(slid_share, (int, float)) and 0 < slid_share <= 1):
        raise ConfigError(f"slid_share must be in (0, 1] (share of the normal force on slid points), "
                          f"got {slid_share!r}")
    if onset not in ("contact", "slide"):
        raise ConfigError(f"onset={onset!r} must be 'contact' (from the contact state) or 'slide' (a slide distance)")
    if handle not in ("auto", "spring", "clamp"):
        raise ConfigError(f"handle={handle!r} must be 'spring' (body force through a handle spring), 'clamp' "
                          "(displacement-controlled clamp on the far end face) or 'auto'")
    vol = grasp_cylinder(radius, length, spacing) if volume is None else volume
    if quasi_static:      # as in the tasks: a quasi-static model needs implicit contact in a contact scene
        cls.require("implicit_contact", task="the grasp-and-pull rig (a quasi-static model in a contact scene)")
    tissue = _build(cls, vol, mat, opts)
    if handle == "auto":
        handle = "clamp" if quasi_static else "spring"
    clamp = _end_clamp(tissue, radius, spacing) if handle == "clamp" else None
    params = ContactParams(stiffness=contact_stiffness, damping=contact_damping)
    cm = ContactModel(tissue.n_nodes, tissue.surface_nodes, [float(mu)], params, tool_static_friction=[float(mu_s)])
    er, mats = _jaw_frames()
    surf = np.asarray(tissue.surface_nodes)             # the contact candidates, each facing one jaw
    facing = er[np.argmax(tissue.rest_positions[surf, :2] @ er[:, :2].T, axis=1)]
    anchors = AnchorSlip(len(surf), params.tangential_stiffness or cm.stiffness_for(dt), slip_distance)
    jaw_half = np.array([0.002, 0.003, 0.5 * length + 0.015])
    kind, tool = np.full(3, BOX), np.zeros(3, dtype=int)
    size = np.tile(jaw_half, (3, 1))
    com = np.zeros((1, 3))
    weights = tissue.masses / tissue.total_mass
    if clamp is not None:
        tissue.set_fixed(clamp)
    forces = np.zeros_like(tissue.positions)
    gvel = np.zeros((3, 6))
    clearance = 0.0005
    travel = clearance + squeeze
    z0 = t0 = None
    rows = []
    res = None
    jaw_z = 0.0                                         # axial jaw travel (clamp mode: the jaws move, not the clamp)
    start = close_time + settle_time
    n_min = int(round((start + pull_time) / dt))
    n_max = int(round((start + max_pull_time) / dt))
    report_every = max(1, int(round(0.05 / dt)))
    n_stop = n_min
    hit_k = None
    snaps = []
    i = 0
    while i < n_stop:
        t = i * dt
        s = min(t / close_time, 1.0)                    # smooth radial closing, then held
        rho = radius + clearance - travel * s * s * (3 - 2 * s)
        gvel[:, 3:] = -er * travel * (6 * s * (1 - s) / close_time if t < close_time else 0.0)
        pulling = i >= int(round(start / dt))
        jaw_vz = -handle_speed if (clamp is not None and pulling) else 0.0
        if pulling and t0 is not None and clamp is not None:
            jaw_z = -handle_speed * (t - t0)
        gvel[:, 5] = jaw_vz
        centres = er * (rho + jaw_half[0])
        centres[:, 2] = jaw_z
        res = cm.compute(tissue.positions, tissue.velocities, kind, tool, size, centres, mats, gvel, com, dt)
        pull = 0.0
        if pulling:
            x = tissue.positions
            zc = weights @ x[:, 2]
            if z0 is None:
                z0, t0 = zc, t
            if clamp is None:
                pull = max(handle_stiffness * (handle_speed * (t - t0) - (zc - z0)), 0.0)
            else:           # the clamp holds the tissue while the jaws slide back: its reaction is the pull
                pull = float(tissue.reaction_forces()[:, 2].sum())
            f = res.forces
            fs = f[surf]
            f_n = np.maximum(-(fs * facing).sum(axis=1), 0.0)       # the jaw faces are parallel to the pull
            slid = anchors.update(x[surf, 2], fs[:, 2], f_n, jaw_z)
            touching = surf[f_n > 0.0]
            speed = float(tissue.velocities[touching, 2].mean()) - jaw_vz if len(touching) else 0.0
            share = float(res.report.slipping[0]) / max(int(res.report.contacts[0]), 1)
            fn = float(res.report.normal_force[0])
            mobilised = float(res.report.tangential_force[0]) / (mu * fn) if mu * fn > 0 else 0.0
            rows.append((t - t0, pull, fn, zc - z0 - jaw_z, share, speed, mobilised, slid))
            if hit_k is None:
                found = slid >= slid_share if onset == "contact" else zc - z0 - jaw_z > onset_slide
                if found:
                    hit_k = len(rows) - 1
                    n_stop = min(max(n_min, i + 1 + int(round(after_onset / dt))), n_max)
                elif i + 1 == n_stop:
                    n_stop = n_max
                if pull > 2.0 * mu_s * fn > 0.0 and hit_k is None:
                    raise ConfigError(
                        f"slip: the grasp holds a pull of {pull:.4g} N, more than twice mu_static * sum(N) = "
                        f"{mu_s * fn:.4g} N, after {t - t0:.3g} s without sliding: something other than friction "
                        f"holds the tissue ({cls.name} resists the pull itself or the jaws catch it); "
                        "this rig measures friction grips only")
            if (len(rows) - 1) % report_every == 0:
                snaps.append((t - t0, anchors.slip.copy(), f_n))
                if progress is not None:
                    progress(t - t0, pull, mu_s * fn)
        np.copyto(forces, res.forces)
        if clamp is None:
            forces[:, 2] += pull * weights
        tissue.step(dt, forces, res.stiffness)
        i += 1
    if res is None or res.report.contacts[0] == 0:
        raise ConfigError("slip: the jaws never touched the tissue; increase squeeze")
    tt, pull, normal, slide, share, speed, mobilised, slid = np.array(rows).T
    if hit_k is None:
        raise ConfigError(f"slip: the grasp did not slide within max_pull_time = {max_pull_time} s of pull "
                          f"(largest pull {pull.max():.4g} N, {pull.max() / max(mu_s * normal.max(), 1e-30):.3g} x "
                          f"mu_static * sum(N)); raise max_pull_time or handle_speed")
    held = int(np.argmax(pull[:hit_k + 1]))
    return SlipResult(tt, pull, normal, slide, float(pull[hit_k]), float(normal[hit_k]), float(mu), vol.n_nodes,
                      cls.name, share, speed, mobilised, onset, float(mu_s), slid, float(pull[held]),
                      float(normal[held]), float(normal[0]), np.array([q[1] for q in snaps]),
                      np.array([q[2] for q in snaps]), np.array([q[0] for q in snaps]),
                      tissue.rest_positions[surf, 2].copy())
