"""Coulomb friction with a stick state and distinct static / kinetic coefficients (numba kernel
for one node-geom contact).

Each node in contact with geom ``g`` owns an anchor point stored in ``g``'s *local* frame, so a
stuck node is dragged along by a moving or rotating jaw. With ``a`` the anchor in world
coordinates, ``n`` the unit contact normal and ``x`` the node position:

    delta_t = (x - a) - ((x - a) . n) n          tangential stretch of the stick spring (m)
    f_trial = -k_t delta_t                        stick force (N)
    cap = mu_s f_n  if the contact was sticking (or is new),  mu f_n  if it was sliding
    |f_trial| <= cap     ->  stick:  f_t = f_trial, anchor unchanged
    |f_trial| >  cap     ->  slide:  f_t = mu f_n f_trial / |f_trial| (kinetic), and the anchor is
                                     moved to a = x - (mu f_n / k_t) delta_t / |delta_t|
                                     (it slides along so the spring just reaches the kinetic cap)

``mu`` is the kinetic coefficient, ``mu_s >= mu`` the static one (the kernel uses max(mu_s, mu),
so a caller that changed only ``mu`` never gets a static cap below the kinetic one). A sticking
contact breaks away once the stick spring exceeds mu_s f_n and then slides at mu f_n; a sliding
contact sticks again as soon as its spring falls back to mu f_n or less (the node stopped moving
relative to the tool, or reversed; to round-off, 1e-9 relative). With mu_s == mu this is the
single-coefficient law.

A new contact starts with its anchor at the node (zero tangential force). The anchor is dropped
when the contact ends (signed distance >= 0), see :mod:`surgsim_envs.contact.model`.
"""

from __future__ import annotations

import math

from numba import njit


#: contact state codes kept per (contact point, geom) by the contact model (``anchor_on``)
NO_CONTACT, STICKING, SLIDING = 0, 1, 2


@njit(cache=True)
def stick_slip(x0, x1, x2, normal, f_n, mu, mu_s, k_t, pos, mat, g, anchor_local, c, state, f_t_out):
    """Tangential (friction) force on one node from one contact; updates its anchor in place.

    (x0, x1, x2) node position, m; normal (3,) unit outward normal of the geom; f_n >= 0 normal
    force magnitude, N; mu kinetic and mu_s static Coulomb coefficient (mu_s >= mu; max(mu_s, mu)
    is used); k_t stick-spring stiffness, N/m; pos[g] (3) / mat[g] (9) pose of geom g (row-major
    rotation, local -> world); anchor_local[c, g] (3) the anchor of candidate c on geom g in the
    geom's local frame (read and written); state: the contact's state before this call,
    NO_CONTACT (0: it starts now, the anchor is placed at the node), STICKING (1) or SLIDING (2).
    Writes the force into f_t_out (3,). Returns True if the node slides (new state SLIDING).
    """
    if state == 0:
        dx, dy, dz = x0 - pos[g, 0], x1 - pos[g, 1], x2 - pos[g, 2]
        anchor_local[c, g, 0] = mat[g, 0] * dx + mat[g, 3] * dy + mat[g, 6] * dz
        anchor_local[c, g, 1] = mat[g, 1] * dx + mat[g, 4] * dy + mat[g, 7] * dz
        anchor_local[c, g, 2] = mat[g, 2] * dx + mat[g, 5] * dy + mat[g, 8] * dz
        f_t_out[0] = 0.0
        f_t_out[1] = 0.0
        f_t_out[2] = 0.0
        return False
    # anchor in world: a = pos + R a_local
    al0, al1, al2 = anchor_local[c, g, 0], anchor_local[c, g, 1], anchor_local[c, g, 2]
    ax = pos[g, 0] + mat[g, 0] * al0 + mat[g, 1] * al1 + mat[g, 2] * al2
    ay = pos[g, 1] + mat[g, 3] * al0 + mat[g, 4] * al1 + mat[g, 5] * al2
    az = pos[g, 2] + mat[g, 6] * al0 + mat[g, 7] * al1 + mat[g, 8] * al2
    ex, ey, ez = x0 - ax, x1 - ay, x2 - az
    en = ex * normal[0] + ey * normal[1] + ez * normal[2]
    tx, ty, tz = ex - en * normal[0], ey - en * normal[1], ez - en * normal[2]
    stretch = math.sqrt(tx * tx + ty * ty + tz * tz)
    cap = mu * f_n
    if state != 2:
        if mu_s > mu:
            cap = mu_s * f_n      # a sticking contact holds up to the static cap
    else:
        cap *= 1.0 + 1e-9         # a stopped sliding contact sticks (its spring is at the cap to round-off)
    if k_t * stretch <= cap:
        f_t_out[0] = -k_t * tx
        f_t_out[1] = -k_t * ty
        f_t_out[2] = -k_t * tz
        return False
    # slide: force at the kinetic cap, anchor slides so that k_t |delta_t| == mu f_n
    cap = mu * f_n
    s = cap / stretch  # = k_t * (cap / k_t) / stretch
    f_t_out[0] = -s * tx
    f_t_out[1] = -s * ty
    f_t_out[2] = -s * tz
    keep = cap / (k_t * stretch)  # fraction of the stretch that remains
    nax = x0 - keep * tx
    nay = x1 - keep * ty
    naz = x2 - keep * tz
    dx, dy, dz = nax - pos[g, 0], nay - pos[g, 1], naz - pos[g, 2]
    anchor_local[c, g, 0] = mat[g, 0] * dx + mat[g, 3] * dy + mat[g, 6] * dz
    anchor_local[c, g, 1] = mat[g, 1] * dx + mat[g, 4] * dy + mat[g, 7] * dz
    anchor_local[c, g, 2] = mat[g, 2] * dx + mat[g, 5] * dy + mat[g, 8] * dz
    return True
