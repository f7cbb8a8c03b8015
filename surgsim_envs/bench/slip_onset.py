"""Gross-slip onset read from the contact state of a grasp (not from a slide distance).

Coulomb's law puts gross slip where the stick zone vanishes: every contact point is at its
friction cap ``|f_t| = mu f_n`` and the contact patch moves relative to the jaws. A fixed slide
distance (2.5 mm) is a poor proxy: at low mu the tissue stick-slips, and 2.5 mm is reached in a
dip after the first release (0.82 x mu*sum(N) at mu = 0.2).

Rule (:func:`gross_slip_index`): the first sample where

* the friction is fully mobilised: |sum of the friction forces| >= ``mobilised`` (default 0.98)
  x mu * sum of the normal forces (the normal-force-weighted share of contact at the cap, which a
  count of sliding nodes is not: light edge nodes slide long before the grip gives way),
* the share of contact points sliding is at least ``share`` (default 0.5; edge nodes with a
  vanishing normal force stick or flicker, at mu = 1.2 only 60-80 % of the nodes slide while the
  grip slides), and
* the contact patch moves along the pull relative to the jaws faster than ``speed_fraction``
  (default 0.2) of the handle speed (a partial-slip creep is much slower),

both held for ``hold`` consecutive samples (default 5), so that one noisy sample does not count.
The pull at that sample is compared with mu * sum(N) there (mu the kinetic coefficient;
``mobilised`` is measured against it). With one coefficient (the default, mu_s = mu) the onset
pull is mu * sum(N). With a static coefficient mu_s > mu (:mod:`surgsim_envs.contact.friction`) a
uniformly loaded patch breaks away at mu_s * sum(N), but a soft grasp gives way between mu and
mu_s times sum(N): its light edge points break away first and slide at mu f_n while the rest
still sticks (docs/contact.md, "Static and kinetic friction").
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.errors import ConfigError

SLIP_SHARE = 0.5
MOBILISED = 0.98
SPEED_FRACTION = 0.2
HOLD_SAMPLES = 5


def gross_slip_index(share, mobilised, patch_speed, handle_speed: float, *, share_threshold: float = SLIP_SHARE,
                     mobilised_threshold: float = MOBILISED, speed_fraction: float = SPEED_FRACTION,
                     hold: int = HOLD_SAMPLES) -> int | None:
    """Index of the first sample of gross slip (see module docstring), or None if the grasp held.

    share: (K,) fraction of contact points sliding; mobilised: (K,) |sum f_t| / (mu sum f_n);
    patch_speed: (K,) m/s of the contact patch along
    the pull, relative to the jaws; handle_speed: m/s of the pulling handle.
    """
    share = np.asarray(share, dtype=float)
    mob = np.asarray(mobilised, dtype=float)
    speed = np.asarray(patch_speed, dtype=float)
    if share.shape != speed.shape or share.shape != mob.shape or share.ndim != 1:
        raise ConfigError(f"share, mobilised and patch_speed must be 1-D arrays of one length, got {share.shape}, "
                          f"{mob.shape}, {speed.shape}")
    if not (0.0 < share_threshold <= 1.0 and speed_fraction > 0 and handle_speed > 0):
        raise ConfigError(f"need 0 < share_threshold <= 1, speed_fraction > 0, handle_speed > 0 m/s; got "
                          f"{share_threshold}, {speed_fraction}, {handle_speed}")
    if not (isinstance(hold, (int, np.integer)) and hold >= 1):
        raise ConfigError(f"hold must be a positive number of samples, got {hold!r}")
    ok = (share >= share_threshold) & (mob >= mobilised_threshold) & (speed >= speed_fraction * handle_speed)
    run = 0
    for k, flag in enumerate(ok):
        run = run + 1 if flag else 0
        if run >= hold:
            return k - hold + 1
    return None
