"""Flat per-world state of the batched backend: W copies of one scene, on one Warp device.

Layout (W worlds, N tissue nodes, E springs, T tets, C contact candidates, G tool geoms, B tool
bodies); every float array is float64 except MuJoCo Warp's own (float32):

* :class:`TissueState` - what a tissue model integrates: positions and velocities (W, N) vec3d,
  plus the model's internal state (for the mass-spring model the Maxwell branch force and
  extension per spring, (W, E), and ``fresh`` (W,) for branches just reset).
* :class:`MassSpringFields` - per-world material (domain randomisation): spring constants K1, K2,
  the Maxwell branch constants kM, kMg (W, E) and the volume stiffness kv (W, T). Shared per scene
  in :class:`MassSpringTopology`: springs, tets, rest lengths/volumes, masses, damping, fixed nodes,
  branch decay, and the CSR incidence lists the node kernel gathers through.
* :class:`ContactState` - stick anchors and states per (world, point, geom), the contact force on
  every node (W, N), each geom's part per point, the per-tool reaction sums and report, and the
  Coulomb friction per world and tool body (W, B: drawn per episode).
* :class:`ToolState` - MuJoCo Warp's model and data (``put_model`` / ``put_data(nworld=W)``) plus
  the rate limiter's float64 controls, goals, rates and ``moving`` flags per world.

Another tissue model follows by giving its own fields/topology records and kernels over the same
:class:`TissueState` (positions, velocities, its internal state arrays).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from surgsim_envs.batch.backend import require


def _put(wp, values, dtype, device):
    return wp.array(np.ascontiguousarray(values), dtype=dtype, device=device)


def _tiled(values, W: int) -> np.ndarray:
    """(W, ...) copies of ``values``."""
    a = np.asarray(values)
    return np.ascontiguousarray(np.broadcast_to(a, (W,) + a.shape))


def csr(rows: np.ndarray, n: int, values: np.ndarray | None = None):
    """(start (n+1,) int32, order (len,) int32) grouping entries by ``rows`` (stable: entries of
    one row keep their order)."""
    order = np.argsort(rows, kind="stable")
    start = np.zeros(n + 1, dtype=np.int64)
    np.add.at(start, rows + 1, 1)
    return np.cumsum(start).astype(np.int32), order.astype(np.int32)


@dataclass
class TissueState:
    """Per-world tissue state (see module docstring)."""

    x: object            # (W, N) vec3d, m
    v: object            # (W, N) vec3d, m/s
    s: object            # (W, E) float64, N: Maxwell branch force
    dl: object           # (W, E) float64, m: branch extension at the last commit
    fresh: object        # (W,) int32: 1 = branches just reset (next step uses a zero interval)
    diverged: object     # (W,) int32: 1 = a node position became NaN/inf since the world's reset

    @classmethod
    def at_rest(cls, rest: np.ndarray, n_springs: int, W: int, device: str) -> "TissueState":
        wp, _ = require()
        return cls(x=_put(wp, _tiled(rest, W), wp.vec3d, device), v=wp.zeros((W, len(rest)), dtype=wp.vec3d, device=device),
                   s=wp.zeros((W, n_springs), dtype=wp.float64, device=device),
                   dl=wp.zeros((W, n_springs), dtype=wp.float64, device=device),
                   fresh=wp.ones(W, dtype=wp.int32, device=device), diverged=wp.zeros(W, dtype=wp.int32, device=device))

    def nbytes(self) -> int:
        return sum(a.capacity for a in (self.x, self.v, self.s, self.dl, self.fresh, self.diverged))


@dataclass
class MassSpringTopology:
    """Per-scene constants of the mass-spring step (see module docstring)."""

    si: object
    sj: object
    L0: object
    decay: object          # (E,) Maxwell branch decay over dt
    tets: object           # (T, 4) int32
    V0: object             # (T,) m^3
    inv_mass: object       # (N,) 1/kg
    b0: object             # (N,) N s/m
    fixed: object          # (N,) int32
    gravity: tuple         # (3,) m/s^2
    spring_start: object   # CSR over nodes: springs at each node, with sign +1 (node si) / -1 (node sj)
    node_springs: object
    spring_sign: object
    corner_start: object   # CSR over nodes: tet corner slots 4 t + k at each node
    node_corners: object
    rest: np.ndarray       # (N, 3) m, the reset positions (fixed nodes at their targets)
    n_nodes: int
    n_springs: int
    n_tets: int


@dataclass
class MassSpringFields:
    """Per-world material of the mass-spring step (W, E) / (W, T)."""

    K1: object
    K2: object
    kM: object
    kMg: object
    kv: object


@dataclass
class ContactState:
    """Per-world contact state and outputs (see module docstring)."""

    anchor: object         # (W, C, G) vec3d, m, stick anchor in the geom's frame
    state: object          # (W, C, G) int32: 0 none, 1 sticking, 2 sliding
    f_ext: object          # (W, N) vec3d, N: contact force on each node
    point_force: object    # (W, C, G) vec3d, N
    point_fn: object       # (W, C, G) float64, N: normal force magnitude
    point_ft: object       # (W, C, G) vec3d, N: friction force
    point_depth: object    # (W, C, G) float64, m
    gpos: object           # (W, G) vec3d, m
    gmat: object           # (W, G) mat33d
    gang: object           # (W, G) vec3d, rad/s
    glin: object           # (W, G) vec3d, m/s (velocity of the geom origin)
    tcom: object           # (W, B) vec3d, m: torque reference (body centre of mass)
    tool_force: object     # (W, B) vec3d, N: force ON each tool body
    tool_torque: object    # (W, B) vec3d, N m
    tool_fn: object        # (W, B) float64, N: sum of normal force magnitudes
    tool_ft: object        # (W, B) float64, N: magnitude of the summed friction force
    tool_contacts: object  # (W, B) int32: points in contact
    tool_slipping: object  # (W, B) int32: points sliding on one of the body's geoms
    tool_depth: object     # (W, B) float64, m: deepest penetration
    geom_fn: object        # (W, G) float64, N: per geom, sum of normal force magnitudes (computed when read)
    geom_ft: object        # (W, G) float64, N: per geom, magnitude of the summed friction force (when read)
    node_mask: object      # (W, N) int32: 1 = the node felt a contact force in the last tissue step (when read)
    mu: object             # (W, B) float64: kinetic Coulomb friction per world and tool body
    mu_s: object           # (W, B) float64: static friction (>= mu)
    sum_force: object      # (W, B) vec3d, N: reaction summed over the tissue sub-steps of a MuJoCo step
    sum_torque: object     # (W, B) vec3d, N m
    gpos0: object          # (W, G) vec3d, m: geom positions at the MuJoCo step's start (sub-cycling)

    @classmethod
    def zeros(cls, W: int, N: int, C: int, G: int, B: int, device: str) -> "ContactState":
        wp, _ = require()
        z = lambda shape, dt: wp.zeros(shape, dtype=dt, device=device)  # noqa: E731
        return cls(anchor=z((W, C, G), wp.vec3d), state=z((W, C, G), wp.int32), f_ext=z((W, N), wp.vec3d),
                   point_force=z((W, C, G), wp.vec3d), point_fn=z((W, C, G), wp.float64),
                   point_ft=z((W, C, G), wp.vec3d), point_depth=z((W, C, G), wp.float64),
                   gpos=z((W, G), wp.vec3d), gmat=z((W, G), wp.mat33d),
                   gang=z((W, G), wp.vec3d), glin=z((W, G), wp.vec3d), tcom=z((W, B), wp.vec3d),
                   tool_force=z((W, B), wp.vec3d), tool_torque=z((W, B), wp.vec3d), tool_fn=z((W, B), wp.float64),
                   tool_ft=z((W, B), wp.float64), tool_contacts=z((W, B), wp.int32),
                   tool_slipping=z((W, B), wp.int32), tool_depth=z((W, B), wp.float64),
                   geom_fn=z((W, G), wp.float64), geom_ft=z((W, G), wp.float64), node_mask=z((W, N), wp.int32),
                   mu=z((W, B), wp.float64), mu_s=z((W, B), wp.float64),
                   sum_force=z((W, B), wp.vec3d), sum_torque=z((W, B), wp.vec3d), gpos0=z((W, G), wp.vec3d))

    def nbytes(self) -> int:
        return sum(getattr(self, k).capacity for k in self.__dataclass_fields__)


@dataclass
class ToolState:
    """MuJoCo Warp model/data of the W worlds and the rate limiter's per-world command state."""

    model: object
    data: object
    ctrl64: object         # (W, nu) float64: the rate-limited controls (MuJoCo Warp keeps float32)
    goal: object           # (W, nu) float64
    rate: object           # (W, nu) float64, units/s
    moving: object         # (W,) int32
