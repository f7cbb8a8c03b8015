"""The stability guard shared by all tissue models.

Checks after every step, cheapest first: non-finite state (every step), runaway speed
(every step), inverted elements and energy blow-up (every ``check_every`` steps). Any failure
raises :class:`TissueUnstableError` naming the model, dt and its critical-dt estimate, so a
diverging simulation never hands NaN to the caller.

The critical dt quoted is that of the *last good state*: the guard keeps a copy of positions and
velocities from the last step that passed every check (refreshed every ``check_every`` steps;
the rest state before that) and evaluates ``model.critical_dt()`` on it, because the estimate on
the diverged state (huge strains) is off by orders of magnitude.

Before a step, :meth:`StabilityGuard.check_inputs` rejects non-finite external forces or contact
stiffness as bad input (:class:`~surgsim_envs.errors.NonFiniteInputError`, naming the array, the
first bad node and its value) while the state is still untouched, so a NaN force is never blamed
on dt and never leaves the model NaN.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
from numba import njit

from surgsim_envs.errors import NonFiniteInputError, TissueUnstableError


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


@njit(cache=True, nogil=True)
def first_non_finite(a):
    """Flat index of the first non-finite entry of the C-contiguous array ``a``, or -1."""
    flat = a.reshape(-1)
    for i in range(flat.shape[0]):
        if not np.isfinite(flat[i]):
            return i
    return -1


_EXPONENT = np.int64(0x7FF0000000000000)


@njit(cache=True, nogil=True)
def all_finite(a) -> bool:
    """True if every entry of the C-contiguous float64 array ``a`` is finite (``first_non_finite(a) <
    0``, without its early exit: the exponent bits of every entry are tested and OR-ed, a loop the
    compiler vectorises)."""
    bits = a.reshape(-1).view(np.int64)
    bad = False
    for i in range(bits.shape[0]):
        bad |= (bits[i] & _EXPONENT) == _EXPONENT
    return not bad


@njit(cache=True, nogil=True)
def speed_within(pos, vel, max_speed2) -> bool:
    """True if every position and velocity is finite and no node's squared speed exceeds
    ``max_speed2`` (m^2/s^2): ``not (v2 > max_speed2)`` for ``v2 = max_speed_squared(pos, vel)``, the
    same decision, as comparisons OR-ed over all nodes (no early exit: vectorised)."""
    bad = False
    for i in range(pos.shape[0]):
        acc = pos[i, 0] + pos[i, 1] + pos[i, 2]
        v2 = vel[i, 0] * vel[i, 0] + vel[i, 1] * vel[i, 1] + vel[i, 2] * vel[i, 2]
        t = acc + v2
        bad |= (v2 > max_speed2) | (not (t - t == 0.0))      # t - t is NaN iff t is inf or NaN
    return not bad


class GuardedModel(Protocol):
    """What the guard reads of a model: its name, step count, time (s), positions (N,3) m and
    velocities (N,3) m/s (written back in place while the critical dt of the last good state is
    evaluated; ``rest_positions`` too where the model has them), and the four estimates below.
    :class:`~surgsim_envs.tissue.base.TissueModel` is one; the guard needs nothing else of it, so it
    sits below the model base class."""

    name: str
    steps: int
    time: float
    positions: np.ndarray
    velocities: np.ndarray

    def critical_dt(self) -> float: ...

    def inverted_elements(self) -> int: ...

    def kinetic_energy(self) -> float: ...

    def elastic_energy(self) -> float: ...


def implicit_step_advice(model, reason: str) -> str | None:
    """The advice for a failure of an implicit step (None: the explicit-step advice): a smaller dt
    cannot cure elements inverted by the load itself."""
    pair = getattr(model, "auto_pair", None)
    active = getattr(model, "active_integrator", None)
    if pair is None or active != pair[1]:
        return None
    if "inverted" in reason:
        return ("The step was implicit already: the load inverts elements, a deformation too large for this "
                "lattice; press less deep, use a coarser lattice, or a model for large strain")
    return ("The step was implicit already; lower the loads or their rate, or soften the material")


class StabilityGuard:
    """max_speed: m/s above which a node is taken as diverging (tissue never moves at 20 m/s).
    max_jump: m, or None: a node may also move this far in one step of any dt (the speed limit is
        ``max(max_speed, max_jump / dt)``). A quasi-static model has no inertia: released, its
        nodes jump to the new equilibrium in one step, a finite-difference speed of the jump over
        dt, not a divergence; a jump beyond the body's own size is one.
    energy_factor: blow-up when kinetic energy exceeds this multiple of the largest
        (kinetic + elastic) energy seen so far plus ``energy_floor`` J, within one check window.
    check_every: steps between the costlier checks (inverted elements, energy).
    """

    def __init__(self, max_speed: float = 20.0, energy_factor: float = 1e3, energy_floor: float = 1e-3,
                 check_every: int = 10, check_inversion: bool = True, max_jump: float | None = None):
        self.max_speed = max_speed
        self.max_jump = max_jump
        self.energy_factor = energy_factor
        self.energy_floor = energy_floor
        self.check_every = max(1, int(check_every))
        self.check_inversion = check_inversion
        self.reset()

    def reset(self) -> None:
        self._energy_ref = 0.0
        self._good_pos: np.ndarray | None = None
        self._good_vel: np.ndarray | None = None
        self._good_time = 0.0

    def state(self) -> tuple:
        """(energy reference J, last good positions (N,3) m or None, velocities (N,3) m/s or None,
        its time s): what :meth:`load_state` takes back (a compiled caller runs the checks itself,
        writing the good state in place, and hands the scalars back)."""
        return self._energy_ref, self._good_pos, self._good_vel, self._good_time

    def load_state(self, energy_ref: float, good_pos, good_vel, good_time: float) -> None:
        """Set what :meth:`state` returns: the largest (kinetic + elastic) energy seen (J) and the
        last state that passed every check (arrays kept by reference; None: none yet)."""
        self._energy_ref = energy_ref
        self._good_pos, self._good_vel = good_pos, good_vel
        self._good_time = good_time

    def check_inputs(self, model: GuardedModel, forces: np.ndarray, stiffness: np.ndarray | None = None) -> None:
        """Raise :class:`NonFiniteInputError` if ``forces`` (N,3) N or ``stiffness`` (N,) N/m hold
        NaN/inf (call before the step: the state stays as it was)."""
        for name, arr, unit in (("external forces", forces, "N"), ("contact stiffness", stiffness, "N/m")):
            if arr is None:
                continue
            if not isinstance(arr, np.ndarray) and hasattr(arr, "count"):   # a contact law (plane_contact_law)
                name, arr = "contact law", arr.data[:arr.count]
            a = np.ascontiguousarray(arr, dtype=np.float64)
            i = int(first_non_finite(a))
            if i >= 0:
                node = i // a.shape[1] if a.ndim == 2 else i
                raise NonFiniteInputError(
                    f"tissue model '{model.name}': {name} hold {a.reshape(-1)[i]!r} {unit} at node {node} "
                    f"(t={model.time:.4g} s); the step was refused and the state is unchanged. Find what produced "
                    "the non-finite value (a contact or tool force, a user-supplied array) and pass finite numbers")

    def _snapshot(self, model: GuardedModel) -> None:
        if self._good_pos is None or self._good_pos.shape != model.positions.shape:
            self._good_pos = model.positions.copy()
            self._good_vel = model.velocities.copy()
        else:
            np.copyto(self._good_pos, model.positions)
            np.copyto(self._good_vel, model.velocities)
        self._good_time = float(model.time)

    def critical_dt_of_last_good_state(self, model: GuardedModel) -> float:
        """``model.critical_dt()`` evaluated on the last state that passed every check (the rest
        state when none has yet); the model's state is restored afterwards. NaN if it fails."""
        pos, vel = model.positions, model.velocities
        good_pos = self._good_pos
        good_vel = self._good_vel
        if good_pos is None or good_pos.shape != pos.shape:
            rest = getattr(model, "rest_positions", None)
            if rest is None or rest.shape != pos.shape:
                good_pos, good_vel = None, None
            else:
                good_pos, good_vel = rest, np.zeros_like(vel)
        if good_pos is None:
            saved = None
        else:
            saved = (pos.copy(), vel.copy())
            np.copyto(pos, good_pos)
            np.copyto(vel, good_vel)
        try:
            crit = float(model.critical_dt())
        except Exception:  # noqa: BLE001 - the estimate itself may fail; the error must still be raised
            crit = float("nan")
        finally:
            if saved is not None:
                np.copyto(pos, saved[0])
                np.copyto(vel, saved[1])
        return crit

    def fail(self, model: GuardedModel, dt: float, reason: str) -> None:
        crit = self.critical_dt_of_last_good_state(model)
        if self._good_pos is not None:
            reason += f" (critical dt evaluated on the last good state, t={self._good_time:.4g} s)"
        else:
            reason += " (critical dt evaluated on the rest state)"
        raise TissueUnstableError(model.name, dt, crit, reason, advice=implicit_step_advice(model, reason))

    def speed_limit(self, dt: float) -> float:
        """m/s: the node speed above which a step of ``dt`` s counts as diverging."""
        if self.max_jump is None or not dt > 0.0:
            return float(self.max_speed)
        return max(float(self.max_speed), float(self.max_jump) / float(dt))

    def check(self, model: GuardedModel, dt: float) -> None:
        vmax2 = max_speed_squared(model.positions, model.velocities)
        if not math.isfinite(vmax2):
            self.fail(model, dt, f"non-finite positions or velocities at t={model.time:.4g} s")
        limit = self.speed_limit(dt)
        if vmax2 > limit ** 2:
            self.fail(model, dt, f"node speed {math.sqrt(vmax2):.3g} m/s exceeds {limit:.4g} m/s at t={model.time:.4g} s")
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
        self._snapshot(model)
