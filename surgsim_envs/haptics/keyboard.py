"""A keyboard "haptic device" driven from MuJoCo's interactive viewer.

Pass :meth:`KeyboardDevice.key_callback` to
``mujoco.viewer.launch_passive(model, data, key_callback=device.key_callback)``. The viewer calls
it with GLFW key codes on key *press*; each press moves the handle one ``step`` (m):

=====================  ===========================================
keys                   action
=====================  ===========================================
Right / Left arrows    +x / -x
Up / Down arrows       +y / -y
Page Up / Page Down    +z / -z   (also ``E`` / ``Q``)
``J`` / ``K``          grip closes / opens by ``grip_step``
Space                  toggles button 0
``B``                  toggles button 1
``R``                  back to the home position, grip open
``[`` / ``]``          halve / double the step (within [0.1 mm, 1 cm])
=====================  ===========================================

Letters W/A/S/D and the digits are left to the viewer's own shortcuts. There is no force
display on a keyboard: forces sent are only recorded (:attr:`force_log`). The passive viewer's
mouse drives its camera and perturbations, not this device; for mouse-like continuous input use
:meth:`move_by` from your own callback. Thread-safe: the viewer thread writes, the servo reads.
"""

from __future__ import annotations

import math
import threading

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.haptics.device import DeviceLimits, DeviceState, HapticDevice

# GLFW key codes (the viewer passes these)
KEY_SPACE, KEY_B, KEY_E, KEY_J, KEY_K, KEY_Q, KEY_R = 32, 66, 69, 74, 75, 81, 82
KEY_LEFT_BRACKET, KEY_RIGHT_BRACKET = 91, 93
KEY_RIGHT, KEY_LEFT, KEY_DOWN, KEY_UP, KEY_PAGE_UP, KEY_PAGE_DOWN = 262, 263, 264, 265, 266, 267

_MOVES = {
    KEY_RIGHT: (1, 0, 0), KEY_LEFT: (-1, 0, 0), KEY_UP: (0, 1, 0), KEY_DOWN: (0, -1, 0),
    KEY_PAGE_UP: (0, 0, 1), KEY_PAGE_DOWN: (0, 0, -1), KEY_E: (0, 0, 1), KEY_Q: (0, 0, -1),
}


#: (keys, action) in the order the help and the viewer overlay list them (module docstring)
KEY_BINDINGS = (
    ("Right / Left", "+x / -x"),
    ("Up / Down", "+y / -y"),
    ("PgUp / PgDn, E / Q", "+z / -z"),
    ("J / K", "grip close / open"),
    ("Space", "toggle button 0"),
    ("B", "toggle button 1"),
    ("R", "back home, grip open"),
    ("[ / ]", "halve / double the step"),
)


def key_help() -> str:
    """The key bindings as text lines (for ``--help`` and the terminal)."""
    width = max(len(k) for k, _ in KEY_BINDINGS)
    return "\n".join(f"  {k:<{width}}  {a}" for k, a in KEY_BINDINGS)


def key_overlay() -> tuple[str, str]:
    """The key bindings as the two columns of a viewer text overlay."""
    return ("\n".join(k for k, _ in KEY_BINDINGS), "\n".join(a for _, a in KEY_BINDINGS))


class KeyboardDevice(HapticDevice):
    """Handle position moved by key presses (see module docstring)."""

    name = "keyboard"

    def __init__(self, limits: DeviceLimits | None = None, home=(0.0, 0.0, 0.0), step: float = 0.001,
                 grip_step: float = 0.1):
        super().__init__(limits)
        home = np.asarray(home, dtype=float)
        if home.shape != (3,) or not np.all(np.isfinite(home)):
            raise ConfigError(f"keyboard home must be a finite (x, y, z) in m, got {home!r}")
        if not (math.isfinite(step) and 1e-4 <= step <= 1e-2):
            raise ConfigError(f"keyboard step must be in [1e-4, 1e-2] m, got {step!r}")
        if not (math.isfinite(grip_step) and 0 < grip_step <= 1):
            raise ConfigError(f"grip_step must be in (0, 1], got {grip_step!r}")
        self.home = self.limits.clamp_position(home)
        self.step, self.grip_step = float(step), float(grip_step)
        self._pos = self.home.copy()
        self._grip = 0.0
        self._buttons = 0
        self._lock = threading.Lock()
        self.keys_handled = 0
        self.keys_ignored = 0

    def key_callback(self, keycode: int) -> None:
        """Handle one GLFW key code (called by the viewer on key press). Unknown keys are ignored."""
        try:
            key = int(keycode)
        except (TypeError, ValueError):
            self.keys_ignored += 1
            return
        if 97 <= key <= 122:  # lower-case ASCII -> GLFW upper-case codes
            key -= 32
        with self._lock:
            if key in _MOVES:
                self._pos = self.limits.clamp_position(self._pos + self.step * np.asarray(_MOVES[key], dtype=float))
            elif key == KEY_J:
                self._grip = min(1.0, self._grip + self.grip_step)
            elif key == KEY_K:
                self._grip = max(0.0, self._grip - self.grip_step)
            elif key == KEY_SPACE:
                self._buttons ^= 1
            elif key == KEY_B:
                self._buttons ^= 2
            elif key == KEY_R:
                self._pos, self._grip = self.home.copy(), 0.0
            elif key == KEY_LEFT_BRACKET:
                self.step = max(1e-4, self.step / 2)
            elif key == KEY_RIGHT_BRACKET:
                self.step = min(1e-2, self.step * 2)
            else:
                self.keys_ignored += 1
                return
            self.keys_handled += 1

    def move_by(self, delta) -> None:
        """Move the handle by ``delta`` (3,) m (clamped to the workspace); for mouse-style input."""
        d = np.asarray(delta, dtype=float).reshape(3)
        if not np.all(np.isfinite(d)):
            raise ConfigError(f"move_by delta must be finite metres, got {d!r}")
        with self._lock:
            self._pos = self.limits.clamp_position(self._pos + d)

    @property
    def position(self) -> np.ndarray:
        """The handle position (3,) m in the device frame (home = origin of the tool's pose)."""
        with self._lock:
            return self._pos.copy()

    def session_summary(self) -> str:
        x, y, z = self.position
        return (f"keyboard: {self.keys_handled} keys handled, {self.keys_ignored} ignored; "
                f"handle at ({x:+.4f}, {y:+.4f}, {z:+.4f}) m from home")

    def _read(self, t: float) -> DeviceState:
        with self._lock:
            return DeviceState(time=t, position=self._pos.copy(), quaternion=np.array([1.0, 0.0, 0.0, 0.0]),
                               buttons=self._buttons, grip=self._grip)
