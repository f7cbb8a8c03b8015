"""A rigid spherical probe pressing a linear static tissue: unilateral, frictionless contact solved
on the tissue's condensed compliance.

The contact law is :class:`~surgsim_envs.contact.unilateral_probe.UnilateralProbe`'s: with ``h_i``
the height of the sphere's lower surface over candidate node ``i``'s rest footprint, ``z_i`` the
node's coordinate along the press axis and ``lambda_i`` the force it pushes the probe with,

    z_i <= h_i,   lambda_i >= 0,   lambda_i (h_i - z_i) = 0,

frictionless: the probe pushes each node along the press axis only, so the nodes under it slide
sideways freely. That probe pins the contact nodes as Dirichlet nodes and re-solves the whole body
per active-set iteration; for a model whose stiffness is factorised once (``fem_static``) every
change of the Dirichlet set would refactorise it. A linear static model gives the displacement of
the candidates for any forces on them from its compliance block ``W`` (capability
``condensed_compliance``):

    z = Z + u0 - W_zz lambda

(frictionless, so only the press axis's compliance columns are needed: one back-substitution per
candidate, not three), so the complementarity problem lives on the candidates alone (a few dozen
unknowns): an active-set
iteration pins the candidate set (solve ``W_AA lambda_A = Z_A + u0_A - h_A``), frees the nodes that
pull the probe and adds the free ones that penetrate it, until neither exists. It starts from the
nodes whose rest position the sphere covers, so the result does not depend on the probe's path;
``W_zz`` is symmetric positive definite, so the solution is unique anyway. The body's displacement
follows from the contact forces through the cached columns. Units: m, N.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs import validate
from surgsim_envs.contact.unilateral_probe import (FORCE_TOLERANCE, MAX_ACTIVE_SET_ITERATIONS,
                                                   PENETRATION_TOLERANCE)
from surgsim_envs.errors import ConfigError


class CompliantUnilateralProbe:
    """A sphere of ``radius`` m pressing the ``candidates`` surface nodes of ``model`` (a tissue with
    the ``condensed_compliance`` capability, e.g. ``fem_static``) along ``-axis``; :meth:`press`
    places it and solves the contact (module docstring). After :meth:`press`, ``nodes`` are the
    nodes in contact, ``lam`` their forces on the probe (N, >= 0), ``settled`` says whether the
    active set converged and ``last_iterations`` how many dense solves it took."""

    def __init__(self, model, candidates, radius: float = 0.005, axis: int = 2):
        model.require("condensed_compliance", task="a compliant unilateral probe")
        self.model = model
        self.radius = validate.positive(radius, "probe radius", unit="m", fix="a sphere radius, e.g. 0.005")
        self.axis = validate.integer(axis, "probe axis", lo=0, hi=2, fix="0, 1 or 2 (2 = z)")
        cand = np.asarray(candidates, dtype=np.int64).reshape(-1)
        self.candidates = cand[~model.fixed[cand]]
        self._others = [a for a in range(3) if a != self.axis]
        self.nodes = np.zeros(0, dtype=np.int64)
        self.lam = np.zeros(0)
        self.settled = True
        self.last_iterations = 0

    def _footprint(self, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Candidates whose rest footprint lies under the sphere and the height (m) of its lower surface there."""
        rest = self.model.rest_positions[self.candidates]
        a, b = self._others
        r2 = (rest[:, a] - c[a]) ** 2 + (rest[:, b] - c[b]) ** 2
        inside = r2 < self.radius * self.radius
        return self.candidates[inside], c[self.axis] - np.sqrt(self.radius * self.radius - r2[inside])

    def move_to(self, centre) -> np.ndarray:
        """Place the sphere away from the tissue (no contact): every node unloaded."""
        self.clear()
        self.model.apply_axial_forces(self.nodes, np.zeros(0), self.axis)
        return self.nodes

    def clear(self) -> None:
        """Forget the contact without solving the tissue (no nodes, no force): for a caller that resets
        the tissue's state itself right after, so that no equilibrium is solved (and no stiffness
        factorised) only to be discarded."""
        self.nodes = np.zeros(0, dtype=np.int64)
        self.lam = np.zeros(0)

    def press(self, centre, max_iterations: int = MAX_ACTIVE_SET_ITERATIONS) -> np.ndarray:
        """Place the sphere's centre at ``centre`` (3,) m and solve the unilateral contact; the tissue's
        positions become the equilibrium. Returns the contact nodes; :meth:`force` is the force on the probe."""
        validate.integer(max_iterations, "max_iterations", lo=1,
                         fix=f"give a positive integer; default {MAX_ACTIVE_SET_ITERATIONS}")
        c = np.asarray(centre, dtype=np.float64).reshape(-1)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise ConfigError(f"probe centre must be 3 finite numbers (m), got {centre!r}")
        cand, h = self._footprint(c)
        ax = self.axis
        if len(cand):
            w, u0 = self.model.compliance_block(cand, axis=ax)             # single-axis columns: frictionless
            z_free = self.model.rest_positions[cand, ax] + u0              # no contact force
        else:
            w, z_free = np.zeros((0, 0)), np.zeros(0)
        pen0 = z_free - h                                                  # > 0: inside the sphere unloaded
        active = h < self.model.rest_positions[cand, ax]                   # the rest surface the sphere covers
        lam = np.zeros(len(cand))
        seen = set()
        self.settled = False
        self.last_iterations = 0
        for it in range(1, int(max_iterations) + 1):
            lam = np.zeros(len(cand))
            if active.any():
                lam[active] = np.linalg.solve(w[np.ix_(active, active)], pen0[active])
            pen = pen0 - w @ lam
            f_tol = FORCE_TOLERANCE * max(float(np.abs(lam).sum()), 1e-300)
            release = active & (lam < -f_tol)
            join = ~active & (pen > PENETRATION_TOLERANCE * self.radius)
            self.last_iterations = it
            if not (release.any() or join.any()):
                self.settled = True
                break
            nxt = active & ~release | join
            if nxt.tobytes() in seen:       # a cycle: change only the worst violation
                nxt = active.copy()
                worst_pull = (-lam[release]).max() / f_tol if release.any() else 0.0
                worst_pen = pen[join].max() / (PENETRATION_TOLERANCE * self.radius) if join.any() else 0.0
                if worst_pull >= worst_pen:
                    nxt[np.flatnonzero(release)[np.argmax(-lam[release])]] = False
                else:
                    nxt[np.flatnonzero(join)[np.argmax(pen[join])]] = True
            seen.add(active.tobytes())
            active = nxt
        self.nodes = cand[active]
        self.lam = lam[active]
        self.model.apply_axial_forces(self.nodes, -self.lam, ax)   # the probe pushes the nodes along -axis
        return self.nodes

    def force(self) -> np.ndarray:
        """(3,) N: the force the tissue exerts on the probe (along +axis, frictionless)."""
        out = np.zeros(3)
        out[self.axis] = float(self.lam.sum())
        return out


__all__ = ["CompliantUnilateralProbe"]
