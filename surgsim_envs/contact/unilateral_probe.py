"""A rigid spherical probe whose contact is unilateral and frictionless along the press axis.

:class:`~surgsim_envs.contact.kinematic_probe.KinematicProbe` pins every node it covers onto the
sphere and keeps it there while the sphere covers it, so a pinned node that the surrounding tissue
pulls away from the sphere pulls the probe with it (a tensile contact), and which nodes are pinned
depends on how the probe arrived. A tool can only push. :class:`UnilateralProbe` solves the
contact as the complementarity problem it is: with ``h_i`` the height of the sphere's lower
surface over node ``i``'s footprint and ``z_i`` the node's coordinate along the press axis,

    z_i <= h_i,   lambda_i >= 0,   lambda_i (h_i - z_i) = 0

where ``lambda_i`` is the (compressive) force the node pushes the probe with. An active-set
iteration finds it: pin the candidate set onto the sphere, solve the tissue's equilibrium, free
the pinned nodes that pull the probe (``lambda_i < 0``) and pin the free nodes that penetrate it
(``z_i > h_i``), until neither exists. Each start is the same (the nodes whose rest position the
sphere covers), so the result does not depend on the probe's path; for a tissue whose equilibrium
is a strictly convex energy under linear constraints (linear springs, rigid extreme-length
links) the complementarity solution is unique anyway.

The contact is frictionless along the press axis for a tissue whose springs act per component
(the ``layered`` model's paper springs, eq. 2.8: a vertical press moves no node sideways), since
a held node keeps its rest footprint coordinates. For a model whose components couple, those
coordinates are held too (no lateral slip under the tool). Units: m, N.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.contact.kinematic_probe import KinematicProbe
from surgsim_envs import validate
from surgsim_envs.errors import ConfigError

#: active-set iterations before the press is reported unsettled (``probe.settled`` False)
MAX_ACTIVE_SET_ITERATIONS = 100
#: a held node is freed when it pulls the probe by more than this fraction of the total contact
#: force (a node carrying ~0 N may sit on either side of zero by round-off; freeing or keeping it
#: changes the force by about this fraction)
FORCE_TOLERANCE = 1e-9
#: a free node joins when it penetrates the sphere by more than this fraction of the radius
PENETRATION_TOLERANCE = 1e-9


class UnilateralProbe(KinematicProbe):
    """A sphere of ``radius`` m pressing the ``candidates`` surface nodes of ``model`` along
    ``-axis``; :meth:`press` places it and solves the unilateral contact (module docstring).

    model: a tissue with ``set_fixed``, ``release``, ``internal_forces`` and ``contact_force``;
    after :meth:`press`, ``nodes`` are the nodes in contact, ``settled`` says whether the active
    set converged and ``last_iterations`` how many solves it took."""

    def __init__(self, model, candidates, radius: float = 0.005, axis: int = 2):
        super().__init__(model, candidates, radius, axis)
        self.settled = True
        self.last_iterations = 0

    def _footprint(self, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Candidates under the sphere (their footprint within the radius) and the height (m) of
        the sphere's lower surface over each."""
        c = centre
        lo = np.searchsorted(self._sorted_key, c[self._sort_axis] - self.radius, side="left")
        hi = np.searchsorted(self._sorted_key, c[self._sort_axis] + self.radius, side="right")
        cand = self._sorted[lo:hi]
        rest = self.model.rest_positions[cand]
        others = [a for a in range(3) if a != self.axis]
        r2 = (rest[:, others[0]] - c[others[0]]) ** 2 + (rest[:, others[1]] - c[others[1]]) ** 2
        inside = r2 < self.radius * self.radius
        cand, r2 = cand[inside], r2[inside]
        return cand, c[self.axis] - np.sqrt(self.radius * self.radius - r2)

    def _hold(self, nodes: np.ndarray, targets: np.ndarray) -> None:
        """Pin exactly ``nodes`` at ``targets``; free the ones held before and not now."""
        left = self.nodes[~np.isin(self.nodes, nodes)]
        self._held[left] = False
        left = left[~self._base_fixed[left]]
        if len(left):
            self.model.release(left)
        if len(nodes):
            self.model.set_fixed(nodes, targets)
        self._held[nodes] = True
        self.nodes = nodes

    def press(self, centre, solve, max_iterations: int = MAX_ACTIVE_SET_ITERATIONS, warm: bool = False) -> np.ndarray:
        """Place the sphere's centre at ``centre`` (3,) m and solve the unilateral contact; ``solve()``
        brings the model to equilibrium with its current Dirichlet nodes (e.g. ``model.static_solve``).
        ``warm``: start the active set from the nodes held now and the ones the sphere's surface
        is above now (it can save solves when the probe moves a little; not when it jumps) instead of from the rest
        surface the sphere covers; the solution is the same. Returns the contact nodes;
        ``force()`` is then the force on the probe (N)."""
        validate.integer(max_iterations, "max_iterations", lo=1,
                         fix=f"give a positive integer; default {MAX_ACTIVE_SET_ITERATIONS}")
        c = np.asarray(centre, dtype=np.float64).reshape(-1)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise ConfigError(f"probe centre must be 3 finite numbers (m), got {centre!r}")
        cand, h = self._footprint(c)
        cand_ok = ~self._base_fixed[cand]
        cand, h = cand[cand_ok], h[cand_ok]
        rest = self.model.rest_positions[cand]
        targets = rest.copy()
        targets[:, self.axis] = h
        if warm:
            active = self._held[cand] | (self.model.positions[cand, self.axis] > h)
        else:   # the same start from any path: the rest surface the sphere covers
            active = h < rest[:, self.axis]
        seen = set()
        self.settled = False
        for it in range(1, int(max_iterations) + 1):
            self._hold(cand[active], targets[active])
            solve()
            held = cand[active]
            lam = self.model.internal_forces()[held, self.axis] if len(held) else np.zeros(0)
            pull = np.zeros(len(cand))
            pull[active] = -lam                               # > 0: the node pulls the probe
            pos = self.model.positions[cand, self.axis]
            pen = np.where(active, 0.0, pos - h)              # > 0: a free node inside the sphere
            f_tol = FORCE_TOLERANCE * max(float(np.abs(lam).sum()), 1e-300)
            release = pull > f_tol
            join = pen > PENETRATION_TOLERANCE * self.radius
            self.last_iterations = it
            if not (release.any() or join.any()):
                self.settled = True
                break
            nxt = active & ~release | join
            key = nxt.tobytes()
            if key in seen:   # a cycle: change only the worst violation
                nxt = active.copy()
                worst_pull = pull.max() / max(f_tol, 1e-300) if release.any() else 0.0
                worst_pen = pen.max() / (PENETRATION_TOLERANCE * self.radius) if join.any() else 0.0
                if worst_pull >= worst_pen:
                    nxt[np.argmax(pull)] = False
                else:
                    nxt[np.argmax(pen)] = True
            seen.add(active.tobytes())
            active = nxt
        return self.nodes


__all__ = ["UnilateralProbe", "MAX_ACTIVE_SET_ITERATIONS", "FORCE_TOLERANCE", "PENETRATION_TOLERANCE"]
