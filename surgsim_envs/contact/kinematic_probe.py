"""A rigid spherical probe held at a pose: the tissue nodes it covers are pinned onto its surface.

The paper-001 way of pressing tissue with a position-controlled haptic tool: the contact mass points
are the surface nodes under the sphere; each is held (Dirichlet) where the sphere's lower surface
passes over its rest position (a node joins only once the sphere reaches its current position), and the tool force is the sum of their spring forces (eq. 2.4-2.5,
``model.contact_force(nodes)``). Works with any model that has ``set_fixed``/``release``. Units m.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.errors import ConfigError


def sphere_contact(rest: np.ndarray, candidates: np.ndarray, centre, radius: float, axis: int = 2):
    """Contact nodes and their targets for a sphere (``centre`` (3,) m, ``radius`` m) pressing along
    ``-axis`` onto the nodes ``candidates`` (their rest positions ``rest[candidates]``).

    A candidate is in contact if it lies within the sphere's footprint and the sphere's lower surface
    there is below its rest height; its target keeps its rest footprint coordinates and takes the
    sphere's surface height. Returns (nodes (K,) int64, targets (K,3) m).
    """
    c = np.asarray(centre, dtype=np.float64).reshape(-1)
    if c.shape != (3,) or not np.all(np.isfinite(c)):
        raise ConfigError(f"probe centre must be 3 finite numbers (m), got {centre!r}")
    if not (np.isfinite(radius) and radius > 0):
        raise ConfigError(f"probe radius must be > 0 m, got {radius!r}")
    cand = np.asarray(candidates, dtype=np.int64)
    x = rest[cand]
    others = [a for a in range(3) if a != axis]
    r2 = (x[:, others[0]] - c[others[0]]) ** 2 + (x[:, others[1]] - c[others[1]]) ** 2
    inside = r2 < radius * radius
    h = np.full(len(cand), np.inf)
    h[inside] = c[axis] - np.sqrt(radius * radius - r2[inside])
    hit = inside & (h < x[:, axis])
    targets = x[hit].copy()
    targets[:, axis] = h[hit]
    return cand[hit], targets


class KinematicProbe:
    """Holds a model's contact nodes on a sphere moved by :meth:`move_to`; ``force()`` in N.

    model: a tissue model with ``set_fixed``, ``release`` and ``contact_force`` (or ``internal_forces``);
    candidates: surface nodes the probe may touch (e.g. the top face); radius: m.
    """

    def __init__(self, model, candidates, radius: float = 0.005, axis: int = 2):
        self.model = model
        self.candidates = np.asarray(candidates, dtype=np.int64)
        self.radius = float(radius)
        self.axis = int(axis)
        self.nodes = np.zeros(0, dtype=np.int64)
        self._base_fixed = model.fixed.copy()
        # candidates sorted along the first footprint axis: a move tests only the slice under the sphere
        self._sort_axis = [a for a in range(3) if a != self.axis][0]
        key = model.rest_positions[self.candidates, self._sort_axis]
        order = np.argsort(key, kind="stable")
        self._sorted = self.candidates[order]
        self._sorted_key = key[order]
        self._held = np.zeros(model.n_nodes, dtype=bool)      # nodes this probe holds
        self._stamp = np.zeros(model.n_nodes, dtype=np.int64)
        self._moves = 0

    def move_to(self, centre) -> np.ndarray:
        """Place the probe; pins the covered nodes, frees the ones it left. Returns the contact nodes."""
        c = np.asarray(centre, dtype=np.float64).reshape(-1)
        lo, hi = (np.searchsorted(self._sorted_key, c[self._sort_axis] + s * self.radius, side=side)
                  for s, side in ((-1.0, "left"), (1.0, "right"))) if c.shape == (3,) else (0, len(self._sorted))
        nodes, targets = sphere_contact(self.model.rest_positions, self._sorted[lo:hi], centre, self.radius, self.axis)
        # a node not yet held joins only if the sphere reaches its CURRENT position: one the deformed
        # surface already carried below the sphere is not touched (pinning it would pull it up)
        new = ~self._held[nodes]
        below = np.zeros(len(nodes), dtype=bool)
        if new.any():   # a model with lazily recovered positions evaluates only these rows
            rows = getattr(self.model, "node_positions", None)
            pos = rows(nodes[new]) if rows is not None else self.model.positions[nodes[new]]
            below[new] = pos[:, self.axis] < targets[new, self.axis]
        keep = ~(new & below)
        nodes, targets = nodes[keep], targets[keep]
        self._moves += 1
        self._stamp[nodes] = self._moves
        left = self.nodes[self._stamp[self.nodes] != self._moves]
        self._held[left] = False
        self._held[nodes] = True
        left = left[~self._base_fixed[left]]
        if len(left):
            self.model.release(left)
        if len(nodes):
            self.model.set_fixed(nodes, targets)
        self.nodes = nodes
        return nodes

    def force(self) -> np.ndarray:
        """(3,) N the tissue exerts on the probe."""
        if len(self.nodes) == 0:
            return np.zeros(3)
        cf = getattr(self.model, "contact_force", None)
        if cf is not None:
            return cf(self.nodes)
        # the held nodes' elastic forces push the tool (-internal_forces() is what the tool applies)
        return self.model.internal_forces()[self.nodes].sum(axis=0)
