"""Force extrapolation: a 1 kHz force signal from a slower physics.

The haptic device needs a new force every millisecond (Zhong et al. 2016 sec. 9.6.3: "at least 1000 Hz";
when the simulation cannot keep up, "force extrapolation (Picinbono et al. 2002) ... generating
the missing forces from the previous time step"). Lin et al. 2008 sec. 2.4 computes the haptic force
from the spring forces of the contact mass points; here that force arrives from the physics as
``coupling_force()`` once per physics update (period ``T``), and the servo (period ``h``, with
``T = r h``) fills the ticks in between.

Let ``(t_k, F_k, x_k)`` be the latest physics sample (its arrival time on the servo clock, the
hand force, the proxy position the physics used), ``F'`` and ``F''`` bounds on the first and
second time derivatives of the true force, ``v`` the hand speed. Three methods:

``hold`` (zero-order hold)
    ``F(t) = F_k``. Error up to ``F' T``; every physics update is a step of up to ``F' T``.

``linear`` (default) — linear extrapolation of the last two samples in time
    ``F(t) = F_k + (F_k - F_{k-1}) / (t_k - t_{k-1}) * min(t - t_k, H)``, horizon ``H`` = the
    last physics interval (so a stalled physics freezes the force after one interval instead of
    running away). Step bound between consecutive servo outputs::

        |dF| <= F' h + min(F'' T^2, 2 F' T)

    (inside an interval the step is the finite-difference slope times ``h``; at an update the
    jump is the prediction error ``|F(t_k) - 2 F(t_{k-1}) + F(t_{k-2})| <= F'' T^2``, and never
    more than ``2 F' T`` where the force has a kink, e.g. contact onset).

``stiffness`` — local contact-stiffness model (Picinbono et al. 2002; Lin et al. 2008's contact
springs)
    ``F(t) = F_k - k n (n . (x(t) - x_k))`` with ``n = F_k / |F_k|`` and ``k`` the local stiffness
    along ``n`` (from ``physics.contact_stiffness()`` when available, else estimated from the
    last two samples ``k = -(dF . n) / (dx . n)``, kept when ``|dx . n| > min_dx`` and clipped to
    ``[0, k_max]``). The normal component is not allowed to change sign (contact only pushes).
    It reacts to the hand at once (no lag). Step bound::

        |dF| <= k_max v h + e_model,   e_model = |F_{k+1} - F_pred(t_{k+1})|

    exact (``e_model = 0``) for a linear elastic contact at rest.

All methods additionally pass through the servo's force-rate clamp ``R`` (N/s), so every step is
also ``<= R h``.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError


class ForceExtrapolator(ABC):
    """Fills servo ticks between physics samples. ``update`` on each physics sample, ``force``
    on each servo tick. Times in s, positions in m, forces in N."""

    name = "base"

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget all samples."""
        self._t: list[float] = []
        self._f: list[np.ndarray] = []
        self._x: list[np.ndarray] = []

    @property
    def n_samples(self) -> int:
        """Samples received (capped at 2 kept)."""
        return len(self._t)

    def update(self, t: float, force, proxy_position, stiffness: float | None = None) -> None:
        """A new physics sample: arrival time ``t`` (s), hand force (3,) N, proxy position (3,) m
        used by that physics state, optional local stiffness (N/m)."""
        f = np.asarray(force, dtype=float).reshape(3)
        x = np.asarray(proxy_position, dtype=float).reshape(3)
        if not (np.all(np.isfinite(f)) and np.all(np.isfinite(x)) and math.isfinite(t)):
            return  # a non-finite sample is ignored: the previous ones stay valid
        if self._t and t <= self._t[-1]:
            # same arrival time: replace the newest sample
            self._t[-1], self._f[-1], self._x[-1] = t, f, x
        else:
            self._t.append(float(t))
            self._f.append(f)
            self._x.append(x)
            if len(self._t) > 2:
                del self._t[0], self._f[0], self._x[0]
        self._on_update(stiffness)

    def _on_update(self, stiffness: float | None) -> None:
        pass

    def force(self, t: float, proxy_position) -> np.ndarray:
        """Extrapolated hand force (3,) N at servo time ``t`` with the proxy at ``proxy_position``."""
        if not self._t:
            return np.zeros(3)
        return self._force(float(t), np.asarray(proxy_position, dtype=float).reshape(3))

    @abstractmethod
    def _force(self, t: float, x: np.ndarray) -> np.ndarray: ...


class HoldExtrapolator(ForceExtrapolator):
    """Zero-order hold: the last physics force."""

    name = "hold"

    def _force(self, t: float, x: np.ndarray) -> np.ndarray:
        return self._f[-1].copy()


class LinearExtrapolator(ForceExtrapolator):
    """Linear in time from the last two samples, horizon capped at the last physics interval
    (or ``max_horizon`` s if smaller)."""

    name = "linear"

    def __init__(self, max_horizon: float | None = None):
        if max_horizon is not None and not (math.isfinite(max_horizon) and max_horizon >= 0):
            raise ConfigError(f"max_horizon must be >= 0 s or None, got {max_horizon!r}")
        self.max_horizon = max_horizon
        super().__init__()

    def _force(self, t: float, x: np.ndarray) -> np.ndarray:
        if len(self._t) < 2:
            return self._f[-1].copy()
        interval = self._t[-1] - self._t[-2]
        horizon = interval if self.max_horizon is None else min(interval, self.max_horizon)
        tau = min(max(t - self._t[-1], 0.0), horizon)
        return self._f[-1] + (self._f[-1] - self._f[-2]) * (tau / interval)


class StiffnessExtrapolator(ForceExtrapolator):
    """Local contact-stiffness model ``F_k - k n (n . (x - x_k))`` (see module docstring)."""

    name = "stiffness"

    def __init__(self, k_max: float = 5000.0, min_dx: float = 2e-6, force_floor: float = 1e-6):
        validate.positive(k_max, "k_max", unit="N/m", fix="the largest stiffness the estimate may report, e.g. 5000")
        validate.positive(min_dx, "min_dx", unit="m", fix="the smallest motion a stiffness is estimated from, e.g. 2e-6")
        self.k_max, self.min_dx, self.force_floor = float(k_max), float(min_dx), float(force_floor)
        self.k = 0.0
        super().__init__()

    def reset(self) -> None:
        super().reset()
        self.k = 0.0

    def _on_update(self, stiffness: float | None) -> None:
        if stiffness is not None and math.isfinite(stiffness):
            self.k = float(np.clip(stiffness, 0.0, self.k_max))
            return
        if len(self._t) < 2:
            return
        f = self._f[-1]
        mag = float(np.linalg.norm(f))
        if mag <= self.force_floor:
            self.k = 0.0
            return
        n = f / mag
        dxn = float(np.dot(self._x[-1] - self._x[-2], n))
        if abs(dxn) > self.min_dx:
            dfn = float(np.dot(self._f[-1] - self._f[-2], n))
            self.k = float(np.clip(-dfn / dxn, 0.0, self.k_max))

    def _force(self, t: float, x: np.ndarray) -> np.ndarray:
        f = self._f[-1]
        mag = float(np.linalg.norm(f))
        if mag <= self.force_floor or self.k == 0.0:
            return f.copy()
        n = f / mag
        fn_new = max(mag - self.k * float(np.dot(x - self._x[-1], n)), 0.0)
        return f + (fn_new - mag) * n


EXTRAPOLATORS = {"hold": HoldExtrapolator, "linear": LinearExtrapolator, "stiffness": StiffnessExtrapolator}


def make_extrapolator(name: str, **kwargs) -> ForceExtrapolator:
    """An extrapolator by name: ``hold``, ``linear`` or ``stiffness``."""
    if name not in EXTRAPOLATORS:
        raise ConfigError(f"unknown force extrapolation {name!r}; choose one of {sorted(EXTRAPOLATORS)}")
    return EXTRAPOLATORS[name](**kwargs)


def linear_step_bound(force_rate: float, force_accel: float, servo_period: float, physics_period: float) -> float:
    """Documented bound (N) on one servo step of the ``linear`` extrapolator:
    ``F' h + min(F'' T^2, 2 F' T)`` with ``F'`` (N/s) and ``F''`` (N/s^2) bounds on the true force."""
    for name, v in (("force_rate", force_rate), ("force_accel", force_accel), ("servo_period", servo_period),
                    ("physics_period", physics_period)):
        if not (math.isfinite(v) and v >= 0):
            raise ConfigError(f"linear_step_bound {name} must be finite and >= 0, got {v!r}")
    return force_rate * servo_period + min(force_accel * physics_period**2, 2.0 * force_rate * physics_period)
