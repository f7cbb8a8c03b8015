"""Contact readings of the force the tissue integrated, not of the penalty at the step's start.

:func:`~surgsim_envs.contact.model._contact_kernel` evaluates the penalty at the positions x^n where
a step starts and reports it per geom (``geom_normal_force``, ``geom_tangential_force``) and per
tool (the report's ``normal_force``, ``tangential_force``). An implicit tissue step integrates the
penalty linearised about x^n instead, ``g = f - k (x - x^n)`` per node, and the tools already get
the reaction of that ``g`` (:func:`~surgsim_envs.contact.model.attribute_increment_kernel`). For a
quasi-static model (``fem_static``, ``layered``) the two differ by far: the body has no inertia, so
a node the jaws met at depth d ends the step at the penalty's equilibrium depth, and ``f = k d``
carries ``k`` times the tool's travel over the step. Measured in Grasp-v0 with ``fem_static``
closing at 5 mm/s: ``f`` read 0.1-25 N per jaw where the tissue integrated 0-0.013 N.

:func:`integrated_readings_kernel` moves every reading onto ``g``: each node's increment
``g_i - f_i`` is split among the (point, geom) pairs that touch it by their part of its contact
stiffness (the split the tools' reaction uses), and each pair's share is added to its geom's and
its tool's normal (along the pair's normal) and tangential (the rest) sums. An explicit step
integrates ``f`` itself: no increment, the readings stay bit for bit. Units: N, N/m.
"""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, nogil=True)
def integrated_readings_kernel(cand, s_nodes, s_w, rows, a0, anchor_on, pair, tool, integrated, forces, stiffness,
                               geom_fn, geom_ft, geom_ftv, tool_fn, tool_ft, tool_ftv):
    """Add to the per-geom and per-tool normal sums (``geom_fn``, ``tool_fn``, N) and tangential
    vector sums (``geom_ftv``, ``tool_ftv``, N) each contact pair's share of the increment
    ``integrated - forces`` of its nodes, and recompute the tangential magnitudes (``geom_ft``,
    ``tool_ft``). ``rows[a0:a0 + rows[1]]`` are the points in contact after the last contact call
    (candidate nodes ``cand`` first, then the surface samples on ``s_nodes`` with weights ``s_w``);
    ``pair[c, g]`` holds the pair's stiffness, unit normal and penalty normal force; the normal force
    the pair integrated is written to ``pair[c, g, 5]`` (the next contact call caps the pair's
    friction with it); ``tool[g]`` the geom's tool. Returns whether any reading changed."""
    C = cand.shape[0]
    G = anchor_on.shape[1]
    changed = False
    for q in range(a0, a0 + rows[1]):
        c = rows[q]
        for g in range(G):
            if anchor_on[c, g] == 0:
                continue
            kg = pair[c, g, 0]
            sx = 0.0
            sy = 0.0
            sz = 0.0
            for m in range(1 if c < C else 3):
                if c < C:
                    i = cand[c]
                    w = 1.0
                else:
                    i = s_nodes[c - C, m]
                    w = s_w[c - C, m]
                k = stiffness[i]
                if k <= 0.0:
                    continue
                share = w * kg / k
                sx += share * (integrated[i, 0] - forces[i, 0])
                sy += share * (integrated[i, 1] - forces[i, 1])
                sz += share * (integrated[i, 2] - forces[i, 2])
            if sx == 0.0 and sy == 0.0 and sz == 0.0:
                continue
            changed = True
            dn = sx * pair[c, g, 1] + sy * pair[c, g, 2] + sz * pair[c, g, 3]
            if pair[c, g, 5] != -2.0:                         # CAP_PENALTY (contact/model.py): not kept
                pair[c, g, 5] = max(0.0, pair[c, g, 4] + dn)    # the normal force the pair integrated
            tx = sx - dn * pair[c, g, 1]
            ty = sy - dn * pair[c, g, 2]
            tz = sz - dn * pair[c, g, 3]
            t = tool[g]
            geom_fn[g] += dn
            tool_fn[t] += dn
            geom_ftv[g, 0] += tx
            geom_ftv[g, 1] += ty
            geom_ftv[g, 2] += tz
            tool_ftv[t, 0] += tx
            tool_ftv[t, 1] += ty
            tool_ftv[t, 2] += tz
    if changed:
        for g in range(G):
            geom_ft[g] = math.sqrt(geom_ftv[g, 0] ** 2 + geom_ftv[g, 1] ** 2 + geom_ftv[g, 2] ** 2)
        for t in range(tool_ft.shape[0]):
            tool_ft[t] = math.sqrt(tool_ftv[t, 0] ** 2 + tool_ftv[t, 1] ** 2 + tool_ftv[t, 2] ** 2)
    return changed


__all__ = ["integrated_readings_kernel"]
