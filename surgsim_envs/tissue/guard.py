"""The stability guard shared by all tissue models.

Checks after every step, cheapest first: non-finite state (every step), runaway speed
(every step), inverted elements and energy blow-up (every ``check_every`` steps). Any failure
raises :class:`TissueUnstableError` naming the model, dt and its critical-dt estimate, so a
diverging simulation never hands NaN to the caller.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from surgsim_envs.errors import TissueUnstableError


@njit(cache=True, nogil=True)
def max_speed_squared(pos, vel):
    """Largest squared node speed (m^2/s^2); inf if any position or velocity is non-finite."""
    vmax2 = 0.0
    for i in range(pos.shape[0]):
        acc = pos[i, 0] + pos[i, 1] + pos[i, 2]
        v2 = vel[i, 0] * vel[i, 0] + vel[i, 1] * vel[i, 1] + vel[i, 2] * vel[i, 2]
        if not np.isfinite(acc + v2):
            return np.inf
        if v2 > vmax2:
            vmax2 = v2
    return vmax2

if TYPE_CHECKING:
    from surgsim_envs.tissue.base import TissueModel


class StabilityGuard:
    """max_speed: m/s above which a node is taken as diverging (tissue never moves at 20 m/s).
    energy_factor: blow-up when kinetic energy exceeds this multiple of the largest
        (kinetic + elastic) energy seen so far plus ``energy_floor`` J, within one check window.
    check_every: steps between the costlier checks (inverted elements, energy).
    """

    def __init__(self, max_speed: float = 20.0, energy_factor: float = 1e3, energy_floor: float = 1e-3,
                 check_every: int = 10, check_inversion: bool = True):
        self.max_speed = max_speed
        self.energy_factor = energy_factor
        self.energy_floor = energy_floor
        self.check_every = max(1, int(check_every))
        self.check_inversion = check_inversion
        self.reset()

    def reset(self) -> None:
        self._energy_ref = 0.0

    def fail(self, model: "TissueModel", dt: float, reason: str) -> None:
        try:
            crit = float(model.critical_dt())
        except Exception:  # the estimate itself may fail on a NaN state
            crit = float("nan")
        raise TissueUnstableError(model.name, dt, crit, reason)

    def check(self, model: "TissueModel", dt: float) -> None:
        vmax2 = max_speed_squared(model.positions, model.velocities)
        if not math.isfinite(vmax2):
            self.fail(model, dt, f"non-finite positions or velocities at t={model.time:.4g} s")
        if vmax2 > self.max_speed ** 2:
            self.fail(model, dt, f"node speed {math.sqrt(vmax2):.3g} m/s exceeds {self.max_speed} m/s at t={model.time:.4g} s")
        if model.steps % self.check_every:
            return
        if self.check_inversion:
            inv = model.inverted_elements()
            if inv:
                self.fail(model, dt, f"{inv} inverted element(s) at t={model.time:.4g} s")
        ke = model.kinetic_energy()
        limit = self.energy_factor * (self._energy_ref + self.energy_floor)
        if ke > limit:
            self.fail(model, dt, f"kinetic energy {ke:.3g} J blew up (limit {limit:.3g} J) at t={model.time:.4g} s")
        self._energy_ref = max(self._energy_ref, ke + model.elastic_energy())
