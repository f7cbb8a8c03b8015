"""The haptic device interface.

A haptic device is read (pose, buttons, grip) and written (a force to render) by the servo loop
(:mod:`surgsim_envs.haptics.servo`) at about 1 kHz. Every device here is *simulated* or a
network/keyboard stand-in for a real one; a driver for real hardware only has to subclass
:class:`HapticDevice` and implement ``_read`` and ``_render``.

Conventions
-----------
* position: metres, in the device frame (the servo maps it into the scene);
* orientation: unit quaternion ``(w, x, y, z)`` (MuJoCo order);
* buttons: integer bit mask (bit 0 = first button);
* grip: jaw opening command in ``[0, 1]`` (0 open, 1 closed);
* force: newtons, in the device frame, the force **on the hand**.

The base class enforces the device's safety limits on every force written: a non-finite force is
replaced by zero and the magnitude is saturated to :attr:`DeviceLimits.max_force` (direction kept).
Every force actually sent is recorded with its time in :attr:`HapticDevice.force_log`.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError
from surgsim_envs.haptics.recording import ForceLog

IDENTITY_QUAT = (1.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class DeviceState:
    """One reading of a device.

    Attributes: ``time`` (s, device or servo clock), ``position`` (3,) m, ``quaternion`` (4,)
    ``(w, x, y, z)``, ``buttons`` (int bit mask), ``grip`` (in [0, 1]).
    """

    time: float
    position: np.ndarray
    quaternion: np.ndarray = field(default_factory=lambda: np.array(IDENTITY_QUAT))
    buttons: int = 0
    grip: float = 0.0

    def is_finite(self) -> bool:
        """True when time, position, quaternion and grip are finite and the quaternion is non-zero."""
        p = np.asarray(self.position, dtype=float)
        q = np.asarray(self.quaternion, dtype=float)
        return (
            p.shape == (3,)
            and q.shape == (4,)
            and bool(np.all(np.isfinite(p)))
            and bool(np.all(np.isfinite(q)))
            and math.isfinite(float(self.time))
            and math.isfinite(float(self.grip))
            and float(np.dot(q, q)) > 1e-12
        )

    def button(self, index: int) -> bool:
        """True when button ``index`` (0-based) is pressed."""
        return bool((int(self.buttons) >> int(index)) & 1)


@dataclass(frozen=True)
class DeviceLimits:
    """Physical limits of a device.

    Attributes: ``workspace_min`` / ``workspace_max`` (3,) m — the box the handle can reach, in
    the device frame; ``max_force`` N — the largest force magnitude the device may render
    (a Phantom Omni/Touch renders about 3.3 N peak, a Phantom Desktop 7.9 N).
    """

    workspace_min: tuple[float, float, float] = (-0.08, -0.06, -0.05)
    workspace_max: tuple[float, float, float] = (0.08, 0.06, 0.10)
    max_force: float = 3.3

    def __post_init__(self) -> None:
        lo = np.asarray(self.workspace_min, dtype=float)
        hi = np.asarray(self.workspace_max, dtype=float)
        if lo.shape != (3,) or hi.shape != (3,) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise ConfigError(
                f"DeviceLimits workspace bounds must be two finite 3-vectors in metres, got "
                f"{self.workspace_min!r} and {self.workspace_max!r}"
            )
        if np.any(hi <= lo):
            raise ConfigError(
                f"DeviceLimits workspace_max {tuple(hi)} must exceed workspace_min {tuple(lo)} on every axis; swap them"
            )
        validate.positive(self.max_force, "DeviceLimits.max_force", unit="N", fix="the device's force limit, e.g. 3.0")

    def clamp_position(self, position: np.ndarray) -> np.ndarray:
        """``position`` (3,) m clipped into the workspace box."""
        return np.clip(np.asarray(position, dtype=float), self.workspace_min, self.workspace_max)

    def saturate(self, force: np.ndarray) -> tuple[np.ndarray, bool]:
        """``(force, saturated)``: ``force`` (3,) N scaled down to at most ``max_force`` (direction kept)."""
        f = np.asarray(force, dtype=float).reshape(3)
        if not np.all(np.isfinite(f)):
            return np.zeros(3), True
        mag = float(np.linalg.norm(f))
        if mag > self.max_force:
            return f * (self.max_force / mag), True
        return f.copy(), False


def normalize_quaternion(q) -> np.ndarray:
    """Unit quaternion ``(w, x, y, z)``; raises :class:`ConfigError` for a zero/non-finite one."""
    q = np.asarray(q, dtype=float).reshape(-1)
    if q.shape != (4,) or not np.all(np.isfinite(q)):
        raise ConfigError(f"quaternion must be 4 finite numbers (w, x, y, z), got {q!r}")
    n = float(np.linalg.norm(q))
    if n < 1e-9:
        raise ConfigError(f"quaternion {q!r} has zero length; use (1, 0, 0, 0) for no rotation")
    return q / n


class HapticDevice(ABC):
    """Base class of haptic devices: ``read`` a pose, ``send_force`` a force.

    Use as a context manager (``with device: ...``) or call :meth:`connect` / :meth:`close`.
    Subclasses implement ``_read(t)`` and ``_render(force, t)``; they may override
    ``_connect``/``_close``.
    """

    #: short name used in logs and the CLI
    name: str = "device"

    def __init__(self, limits: DeviceLimits | None = None):
        self.limits = limits if limits is not None else DeviceLimits()
        if not isinstance(self.limits, DeviceLimits):
            raise ConfigError(f"limits must be a DeviceLimits, got {type(self.limits).__name__}")
        self.force_log = ForceLog()
        self._connected = False
        self._last_force = np.zeros(3)
        self.last_saturated = False

    # -- lifecycle ----------------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        """True between :meth:`connect` and :meth:`close`."""
        return self._connected

    def connect(self) -> "HapticDevice":
        """Open the device (idempotent). Returns ``self``."""
        if not self._connected:
            self._connect()
            self._connected = True
        return self

    def close(self) -> None:
        """Render zero force and release the device (idempotent)."""
        if self._connected:
            try:
                self._render(np.zeros(3), float("nan"))
            finally:
                self._close()
                self._connected = False

    def __enter__(self) -> "HapticDevice":
        return self.connect()

    def __exit__(self, *exc) -> None:
        self.close()

    def session_summary(self) -> str | None:
        """One line on what the device saw during the run (printed by teleop), or None."""
        return None

    def _connect(self) -> None:  # pragma: no cover - trivial default
        pass

    def _close(self) -> None:  # pragma: no cover - trivial default
        pass

    # -- I/O ----------------------------------------------------------------------------------
    def read(self, t: float) -> DeviceState:
        """The device state at servo time ``t`` (s). Simulated devices evaluate their script at
        ``t``; live devices (UDP, keyboard) return their latest sample. The state may be
        non-finite (the servo rejects such poses)."""
        if not self._connected:
            raise ConfigError(f"{self.name} device is not connected; call connect() or use 'with device:'")
        return self._read(float(t))

    def send_force(self, force, t: float) -> np.ndarray:
        """Render ``force`` (3,) N on the hand at time ``t`` (s). Non-finite forces become zero,
        magnitudes above ``limits.max_force`` are saturated. Returns the force actually sent."""
        if not self._connected:
            raise ConfigError(f"{self.name} device is not connected; call connect() or use 'with device:'")
        sent, saturated = self.limits.saturate(force)
        self.last_saturated = saturated
        self._render(sent, float(t))
        self._last_force = sent
        self.force_log.append(float(t), sent, saturated)
        return sent

    @property
    def last_force(self) -> np.ndarray:
        """The last force sent (3,) N."""
        return self._last_force.copy()

    @abstractmethod
    def _read(self, t: float) -> DeviceState:
        """Return the state at servo time ``t``."""

    def _render(self, force: np.ndarray, t: float) -> None:
        """Deliver ``force`` (already limited) to the hardware; simulated devices only record it."""
