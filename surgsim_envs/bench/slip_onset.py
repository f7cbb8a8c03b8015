"""Gross-slip onset of a grasp, read from how far its contact points have slid along the jaws.

Coulomb's law puts gross slip where the stick zone vanishes: every contact point slides relative
to the jaws. Each contact point carries a friction anchor fixed in its jaw's frame while it sticks
(:mod:`surgsim_envs.contact.friction`); the anchor moves along the jaw only while the point slides,
so the anchor's travel is the point's slip, free of the elastic stretch of the tissue and of the
stick spring. The anchor is recovered from public contact outputs: the friction force on a point is
``f_t = -k_t (x - a)`` (sticking or sliding), so along the pull axis, to which the jaws' normals
are perpendicular, ``a = x + f_t / k_t``.

Rule (:func:`gross_slip_index` on :meth:`AnchorSlip.update`'s output): the grasp has slid at the
first sample where the contact points that have each slid at least ``SLIP_DISTANCE`` (0.1 mm) along
the pull since the pull began carry at least ``SLID_SHARE`` (0.9) of the jaws' normal force. The
onset pull is the pull at that sample; the *held* force is the largest pull up to it.

Why these numbers: a point that sticks does not move its anchor at all, so the distance only has
to exceed round-off and the stick-slip flicker of a point at its cap; 0.1 mm is 1/30 of the rig's
lattice spacing and above the stick spring's stretch at the cap (``mu f_n / k_t``: about mu x
0.07 mm for the rig's 4 mN points on 60 N/m). Weighting by normal force keeps the lightly loaded
points at the edges of each jaw's contact strip, which slide first (partial slip), from counting
as the grip giving way. 0.9 leaves the last tenth of the normal force, where points flicker
between stick and slip, out of the decision. The grasp gives way gradually, so the thresholds
matter: a share of 0.8-0.95 or a distance of 0.05-0.2 mm moves the held force by up to 8 % of
mu * sum(N) in the mass-spring rig, under 2 % in fem (docs/material_tests.md, "Slip onset").

Nothing here reads the friction force's ratio to mu * N: a grip whose friction sits at the cap
while its points do not move has not slid, and points that slide count whatever the friction sum.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError

#: m, slip of a contact point's anchor along the pull that counts the point as slid
SLIP_DISTANCE = 1e-4
#: share of the jaws' normal force carried by slid points at which the grasp has slid
SLID_SHARE = 0.9


class AnchorSlip:
    """Slip (m) of every contact point of a grasp along the pull axis, from its friction anchor.

    ``n_points``: contact points (tissue nodes) that can touch; ``k_t`` (N/m): the stick spring of the
    contact law; ``slip_distance`` (m): slip at which a point counts as slid. Call :meth:`update` once
    per sample from the start of the pull.
    """

    def __init__(self, n_points: int, k_t: float, slip_distance: float = SLIP_DISTANCE):
        validate.integer(n_points, "n_points", lo=1, fix="the number of contact points")
        validate.positive(k_t, "k_t", unit="N/m", fix="the stick-spring stiffness")
        if not (np.isfinite(slip_distance) and slip_distance > 0):
            raise ConfigError(f"slip_distance must be > 0 m (e.g. {SLIP_DISTANCE}), got {slip_distance!r}")
        self.k_t = float(k_t)
        self.slip_distance = float(slip_distance)
        self.touching = np.zeros(n_points, dtype=bool)
        self.ref = np.zeros(n_points)          # anchor (m, jaw frame) when the current contact began
        self.last = np.zeros(n_points)         # anchor at the previous sample
        self.done = np.zeros(n_points)         # slip accumulated over earlier contacts of the point
        self.slip = np.zeros(n_points)         # total slip along the pull, m

    def update(self, axial_position, axial_friction, normal_force, jaw_axial: float = 0.0) -> float:
        """Share of the jaws' normal force carried by points that have slid ``slip_distance``.

        axial_position (n,) m: each point's coordinate along the pull; axial_friction (n,) N: the
        friction force on it along the pull; normal_force (n,) N: its normal force (> 0 = touching);
        jaw_axial (m): the jaws' displacement along the pull since the start (they may move).
        """
        x = np.asarray(axial_position, dtype=float)
        f_t = np.asarray(axial_friction, dtype=float)
        f_n = np.asarray(normal_force, dtype=float)
        if not (x.shape == f_t.shape == f_n.shape == self.touching.shape):
            raise ConfigError(f"axial_position, axial_friction and normal_force must each have shape "
                              f"{self.touching.shape}, got {x.shape}, {f_t.shape}, {f_n.shape}")
        anchor = x + f_t / self.k_t - jaw_axial
        now = f_n > 0.0
        lost = self.touching & ~now
        self.done[lost] += self.last[lost] - self.ref[lost]
        new = now & ~self.touching
        self.ref[new] = anchor[new]
        self.last[now] = anchor[now]
        self.touching = now
        self.slip[now] = self.done[now] + anchor[now] - self.ref[now]
        total = f_n[now].sum()
        if total <= 0.0:
            return 0.0
        return float(f_n[now & (self.slip >= self.slip_distance)].sum() / total)


def gross_slip_index(slid_share, share: float = SLID_SHARE) -> int | None:
    """Index of the first sample at which ``slid_share`` (per sample, from :meth:`AnchorSlip.update`)
    reaches ``share``; None if the grasp never slid."""
    s = np.asarray(slid_share, dtype=float)
    if s.ndim != 1:
        raise ConfigError(f"slid_share must be a 1-D array (one value per sample), got shape {s.shape}")
    if not (0.0 < share <= 1.0):
        raise ConfigError(f"share must be in (0, 1] (the share of normal force on slid points), got {share!r}")
    hit = np.flatnonzero(s >= share)
    return int(hit[0]) if len(hit) else None
