"""Whether a quasi-static step's contact set still holds at the positions the step reached.

A quasi-static tissue step (``fem_static``) solves the equilibrium with the penalty linearised
about the step's start, on the contact points found there. A point that meets a tool only during
the step gets no force, and a point the solve pulls out of a tool keeps a (tensile) one. With no
inertia to smooth it, the next step swings back: a node released at the rim of a sliding probe
springs into it, is pushed out, springs back. Measured in Palpation-v0 (the default ``fem_static``,
the probe sliding pressed at half speed over 1.4 s): 365 such on-off-on flips, the probe's force
jumping by up to 82 % of its mean from one 1 ms step to the next. The scene therefore solves such a
step again from its start, linearised about the positions it reached, until the points inside a
tool there are the points the step was solved with (:data:`MAX_CONTACT_SET_SOLVES` solves at most):
a semismooth Newton iteration on the piecewise-linear penalty, which ends on the penalty's own
equilibrium for the step.

:func:`contact_set_changes` counts the points whose inside-a-tool state at given positions differs
from the contact state the last contact call left (``anchor_on``), with the contact kernel's own
shape tests; it writes nothing. Units: m.
"""

from __future__ import annotations

from numba import njit

from surgsim_envs.contact.shapes import local_outside, world_sdf
from surgsim_envs.contact.surface_points import contact_point

#: solves of one quasi-static step at most (the first, then re-solves while the contact set moves)
MAX_CONTACT_SET_SOLVES = 4


@njit(cache=True, nogil=True)
def contact_set_changes(positions, cand, s_nodes, s_w, kind, size, gpos, gmat, anchor_on, vec3):
    """Number of contact points (candidate nodes ``cand``, then the surface samples on ``s_nodes``
    with weights ``s_w``) inside some geom at ``positions`` (N,3) m but in contact with none after
    the last contact call (``anchor_on`` (C + S, G)), or the reverse. ``vec3`` (>= 4, 3) scratch
    rows. Geoms posed by ``gpos`` (G,3) m and row-major ``gmat`` (G,9), shaped by ``kind``, ``size``."""
    C = cand.shape[0]
    P = C + s_nodes.shape[0]
    G = kind.shape[0]
    nl, cl, nrm, cpt = vec3[0], vec3[1], vec3[2], vec3[3]
    changes = 0
    for c in range(P):
        x0, x1, x2 = contact_point(c, C, cand, s_nodes, s_w, positions)[:3]
        inside = False
        was = False
        for g in range(G):
            if anchor_on[c, g] != 0:
                was = True
            if inside:
                continue
            dx = x0 - gpos[g, 0]
            dy = x1 - gpos[g, 1]
            dz = x2 - gpos[g, 2]
            qx = gmat[g, 0] * dx + gmat[g, 3] * dy + gmat[g, 6] * dz
            qy = gmat[g, 1] * dx + gmat[g, 4] * dy + gmat[g, 7] * dz
            qz = gmat[g, 2] * dx + gmat[g, 5] * dy + gmat[g, 8] * dz
            if local_outside(kind[g], size[g, 0], size[g, 1], size[g, 2], qx, qy, qz):
                continue
            if world_sdf(kind[g], size, gpos, gmat, g, x0, x1, x2, nl, cl, nrm, cpt) < 0.0:
                inside = True
        if inside != was:
            changes += 1
    return changes


__all__ = ["MAX_CONTACT_SET_SOLVES", "contact_set_changes"]
