"""Building the contact's plane law (:mod:`surgsim_envs.contact_law.plane`) from a contact model's
state after a compute: the pairs in contact, with their stick anchors from before the step, and the
open pairs of candidate nodes near a tool. Units: m, N, N/m."""

from __future__ import annotations

import numpy as np
from numba import njit

from surgsim_envs.contact.shapes import bounding_radius, world_sdf
from surgsim_envs.contact_law.plane import F0, FN0, KN, KT, MU, MU_CAP, pair_force

#: m, a candidate node this close to a tool (signed distance) but not touching it where the law is
#: built enters the law as an open pair (f_n0 < 0): it closes if the step moves it onto the tool
POTENTIAL_MARGIN = 1e-3


@njit(cache=True, nogil=True)
def build_plane_law(cand, rows, a0, anchor_on, pair, anchor_on_before, anchor_local_before, positions, gpos, gmat,
                    tool, k_n, k_t, mu, mu_s, nodes, data, kind, size, margin, vec):
    """Write the plane law of every pair in contact after the last contact call into ``nodes`` /
    ``data`` (:class:`PlaneContactLaw`); returns their count, or -1 if a surface sample is in
    contact (not supported). ``rows[a0:a0 + rows[1]]`` the points in contact (candidate nodes
    ``cand`` first); ``anchor_on`` / ``pair`` the last call's states and pair data (stiffness, normal,
    normal force); ``anchor_on_before`` / ``anchor_local_before`` the friction state before that call
    (``ContactModel.friction_state()``); ``positions`` (N,3) m where the call ran; ``gpos`` / ``gmat``
    the geoms' poses; ``tool`` (G,) each geom's tool; ``k_n``, ``k_t`` per contact point, N/m;
    ``mu``, ``mu_s`` (T,) kinetic and static friction per tool. Candidate nodes within ``margin`` (m)
    of a geom they do not touch (``kind`` (G,), ``size`` (G,3) the geoms' shapes; ``vec`` (4,3)
    scratch) are added as open pairs on the geom's tangent plane at their closest point."""
    C = cand.shape[0]
    G = anchor_on.shape[1]
    p = 0
    f = np.empty(3)
    for q in range(a0, a0 + rows[1]):
        c = rows[q]
        for g in range(G):
            state = anchor_on[c, g]
            if state == 0:
                continue
            if c >= C:
                return -1
            i = cand[c]
            row = data[p]
            n0, n1, n2 = pair[c, g, 1], pair[c, g, 2], pair[c, g, 3]
            row[0], row[1], row[2] = n0, n1, n2
            base = k_n if (state == 2 or k_n > k_t) else k_t
            row[KN] = pair[c, g, 0] - base + k_n          # k_n plus the implicit damping's c_n / dt
            row[FN0] = pair[c, g, 4]
            before = anchor_on_before[c, g]
            if before == 0:
                row[5] = row[6] = row[7] = 0.0
            else:
                al0, al1, al2 = (anchor_local_before[c, g, 0], anchor_local_before[c, g, 1],
                                 anchor_local_before[c, g, 2])
                e0 = positions[i, 0] - (gpos[g, 0] + gmat[g, 0] * al0 + gmat[g, 1] * al1 + gmat[g, 2] * al2)
                e1 = positions[i, 1] - (gpos[g, 1] + gmat[g, 3] * al0 + gmat[g, 4] * al1 + gmat[g, 5] * al2)
                e2 = positions[i, 2] - (gpos[g, 2] + gmat[g, 6] * al0 + gmat[g, 7] * al1 + gmat[g, 8] * al2)
                en = e0 * n0 + e1 * n1 + e2 * n2
                row[5], row[6], row[7] = e0 - en * n0, e1 - en * n1, e2 - en * n2
            t = tool[g]
            row[KT] = k_t
            row[MU] = mu[t]
            row[MU_CAP] = mu[t] if (before == 2 or mu_s[t] < mu[t]) else mu_s[t]
            pair_force(row, 0.0, 0.0, 0.0, f)
            row[F0], row[F0 + 1], row[F0 + 2] = f[0], f[1], f[2]
            nodes[p] = i
            p += 1
    # candidate nodes near a geom but not on it: open pairs (f_n0 = -k_n phi < 0, no stretch, new)
    if margin > 0.0:
        nl, cl, nrm, cpt = vec[0], vec[1], vec[2], vec[3]
        for c in range(C):
            i = cand[c]
            x0, x1, x2 = positions[i, 0], positions[i, 1], positions[i, 2]
            for g in range(G):
                if anchor_on[c, g] != 0:
                    continue
                rg = bounding_radius(kind[g], size[g, 0], size[g, 1], size[g, 2]) + margin
                dx, dy, dz = x0 - gpos[g, 0], x1 - gpos[g, 1], x2 - gpos[g, 2]
                if dx * dx + dy * dy + dz * dz >= rg * rg:
                    continue
                phi = world_sdf(kind[g], size, gpos, gmat, g, x0, x1, x2, nl, cl, nrm, cpt)
                if phi >= margin or phi < 0.0:
                    continue
                row = data[p]
                row[0], row[1], row[2] = nrm[0], nrm[1], nrm[2]
                row[KN] = k_n
                row[FN0] = -k_n * phi
                row[5] = row[6] = row[7] = 0.0
                t = tool[g]
                row[KT] = k_t
                row[MU] = mu[t]
                row[MU_CAP] = mu[t] if mu_s[t] < mu[t] else mu_s[t]
                row[F0] = row[F0 + 1] = row[F0 + 2] = 0.0
                nodes[p] = i
                p += 1
    return p


__all__ = ["POTENTIAL_MARGIN", "build_plane_law"]
