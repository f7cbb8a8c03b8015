"""A scripted haptic device: a hand that follows waypoints, with optional tremor and drift.

The script is a small spec (a dict, TOML table or :class:`TrajectorySpec`)::

    {"waypoints": [[0, 0, 0.02], [0, 0, -0.005], [0, 0, 0.02]],   # m, device frame
     "speeds": 0.01,             # m/s per segment (scalar or one per segment)
     "dwell": [0.2, 0.5, 0.0],   # s held at each waypoint (scalar or one per waypoint)
     "grip": [0, 1, 1],          # optional jaw command per waypoint, in [0, 1] (linear in between)
     "buttons": 0,               # bit mask held throughout
     "tremor_amplitude": 0.0003, # m, per-axis amplitude of physiological tremor (8-12 Hz)
     "tremor_frequency": [8, 12],# Hz band; each axis draws its frequency from it
     "drift_speed": 0.0005,      # m/s, slow constant drift in a random direction
     "profile": "linear",        # or "minimum_jerk"
     "seed": 0}

Motion between waypoints follows straight lines, at constant speed (``"profile": "linear"``) or
with the minimum-jerk profile of human reaching (``"profile": "minimum_jerk"``: same segment
duration ``length / speed``, zero speed and acceleration at the waypoints, peak speed 1.875x).
Tremor is ``A * sin(2 pi f_i t + phi_i)`` per axis with ``f_i`` and ``phi_i`` drawn from the seed;
drift is ``v_d * t`` along a seeded random unit vector. The pose is a pure function of the time,
so the same seed gives the same trajectory bit for bit, whatever order the times are read in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.haptics.device import IDENTITY_QUAT, DeviceLimits, DeviceState, HapticDevice, normalize_quaternion


def _per_item(value, n: int, name: str, unit: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float).reshape(-1)
    if arr.size == 1:
        arr = np.full(n, float(arr[0]))
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise ConfigError(f"trajectory '{name}' must be a finite scalar or {n} values in {unit}, got {value!r}")
    return arr


@dataclass
class TrajectorySpec:
    """Scripted hand motion (see module docstring). Units: m, m/s, s, Hz."""

    waypoints: list
    speeds: float | list = 0.01
    dwell: float | list = 0.0
    grip: float | list | None = None
    buttons: int = 0
    quaternion: tuple = IDENTITY_QUAT
    tremor_amplitude: float = 0.0
    tremor_frequency: tuple = (8.0, 12.0)
    drift_speed: float = 0.0
    seed: int = 0
    profile: str = "linear"
    # derived
    _points: np.ndarray = field(init=False, repr=False)
    _speeds: np.ndarray = field(init=False, repr=False)
    _dwell: np.ndarray = field(init=False, repr=False)
    _grip: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        pts = np.asarray(self.waypoints, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 1 or not np.all(np.isfinite(pts)):
            raise ConfigError(
                f"trajectory 'waypoints' must be a list of [x, y, z] positions in m (at least one), got {self.waypoints!r}"
            )
        n = len(pts)
        speeds = _per_item(self.speeds, max(n - 1, 1), "speeds", "m/s")[: max(n - 1, 0)]
        if np.any(speeds <= 0):
            raise ConfigError(f"trajectory 'speeds' must be > 0 m/s, got {self.speeds!r}")
        dwell = _per_item(self.dwell, n, "dwell", "s")
        if np.any(dwell < 0):
            raise ConfigError(f"trajectory 'dwell' must be >= 0 s, got {self.dwell!r}")
        grip = _per_item(0.0 if self.grip is None else self.grip, n, "grip", "[0, 1]")
        if np.any((grip < 0) | (grip > 1)):
            raise ConfigError(f"trajectory 'grip' must lie in [0, 1], got {self.grip!r}")
        if not (math.isfinite(self.tremor_amplitude) and self.tremor_amplitude >= 0):
            raise ConfigError(f"tremor_amplitude must be >= 0 m, got {self.tremor_amplitude!r}")
        fband = np.asarray(self.tremor_frequency, dtype=float).reshape(-1)
        if fband.size == 1:
            fband = np.array([fband[0], fband[0]])
        if fband.shape != (2,) or not np.all(np.isfinite(fband)) or fband[0] <= 0 or fband[1] < fband[0]:
            raise ConfigError(
                f"tremor_frequency must be a positive band [f_lo, f_hi] in Hz (physiological tremor is 8-12 Hz), got {self.tremor_frequency!r}"
            )
        if not (math.isfinite(self.drift_speed) and self.drift_speed >= 0):
            raise ConfigError(f"drift_speed must be >= 0 m/s, got {self.drift_speed!r}")
        if self.profile not in ("linear", "minimum_jerk"):
            raise ConfigError(f"trajectory 'profile' must be 'linear' or 'minimum_jerk', got {self.profile!r}")
        if int(self.buttons) < 0:
            raise ConfigError(f"buttons must be a non-negative bit mask, got {self.buttons!r}")
        self.quaternion = tuple(normalize_quaternion(self.quaternion))
        self.tremor_frequency = (float(fband[0]), float(fband[1]))
        self._points, self._speeds, self._dwell, self._grip = pts, speeds, dwell, grip

    @classmethod
    def from_dict(cls, data: dict) -> "TrajectorySpec":
        """Build from a plain dict (e.g. a TOML table); unknown keys raise :class:`ConfigError`."""
        if not isinstance(data, dict):
            raise ConfigError(f"trajectory spec must be a dict, got {type(data).__name__}")
        allowed = {"waypoints", "speeds", "dwell", "grip", "buttons", "quaternion", "tremor_amplitude",
                   "tremor_frequency", "drift_speed", "seed", "profile"}
        unknown = set(data) - allowed
        if unknown:
            raise ConfigError(f"unknown trajectory keys {sorted(unknown)}; allowed: {sorted(allowed)}")
        if "waypoints" not in data:
            raise ConfigError("trajectory spec needs 'waypoints': a list of [x, y, z] positions in m")
        return cls(**data)

    # -- timing -------------------------------------------------------------------------------
    def segment_times(self) -> np.ndarray:
        """Times (s) at which each phase ends: dwell0, move0, dwell1, move1, ..., dwell_last."""
        lengths = np.linalg.norm(np.diff(self._points, axis=0), axis=1)
        durations = []
        for i in range(len(self._points)):
            durations.append(self._dwell[i])
            if i < len(lengths):
                durations.append(lengths[i] / self._speeds[i])
        return np.cumsum(durations)

    @property
    def duration(self) -> float:
        """Total scripted time (s); the pose is held at the last waypoint afterwards."""
        return float(self.segment_times()[-1])

    def nominal(self, t: float) -> tuple[np.ndarray, float]:
        """Noise-free position (3,) m and grip at time ``t`` (s)."""
        ends = self.segment_times()
        phase = int(np.searchsorted(ends, t, side="right"))
        if phase >= len(ends):
            return self._points[-1].copy(), float(self._grip[-1])
        wp = phase // 2
        if phase % 2 == 0:  # dwell at waypoint wp
            return self._points[wp].copy(), float(self._grip[wp])
        start = ends[phase - 1]
        span = ends[phase] - start
        s = 0.0 if span <= 0 else (t - start) / span
        if self.profile == "minimum_jerk":  # human reaching: 10 s^3 - 15 s^4 + 6 s^5, zero end speed/accel
            s = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)
        pos = self._points[wp] + s * (self._points[wp + 1] - self._points[wp])
        return pos, float(self._grip[wp] + s * (self._grip[wp + 1] - self._grip[wp]))


class ScriptedDevice(HapticDevice):
    """A simulated hand following a :class:`TrajectorySpec`; the script clock is the servo time
    (``read(t)``) minus ``start_time``. Forces sent are recorded in :attr:`force_log`."""

    name = "scripted"

    def __init__(self, spec: TrajectorySpec | dict, limits: DeviceLimits | None = None, start_time: float = 0.0):
        super().__init__(limits)
        self.spec = spec if isinstance(spec, TrajectorySpec) else TrajectorySpec.from_dict(spec)
        if not math.isfinite(start_time):
            raise ConfigError(f"start_time must be finite seconds, got {start_time!r}")
        self.start_time = float(start_time)
        rng = np.random.default_rng(int(self.spec.seed))
        lo, hi = self.spec.tremor_frequency
        self._tremor_freq = rng.uniform(lo, hi, size=3)
        self._tremor_phase = rng.uniform(0.0, 2 * math.pi, size=3)
        d = rng.normal(size=3)
        self._drift_dir = d / max(float(np.linalg.norm(d)), 1e-12)

    @property
    def duration(self) -> float:
        """Scripted duration (s)."""
        return self.spec.duration

    def position(self, t: float) -> np.ndarray:
        """Hand position (3,) m at script time ``t`` (s), including tremor and drift."""
        pos, _ = self.spec.nominal(t)
        if self.spec.tremor_amplitude > 0:
            pos = pos + self.spec.tremor_amplitude * np.sin(2 * math.pi * self._tremor_freq * t + self._tremor_phase)
        if self.spec.drift_speed > 0:
            pos = pos + self.spec.drift_speed * max(t, 0.0) * self._drift_dir
        return pos

    def _read(self, t: float) -> DeviceState:
        ts = t - self.start_time
        _, grip = self.spec.nominal(ts)
        return DeviceState(
            time=t,
            position=self.position(ts),
            quaternion=np.array(self.spec.quaternion),
            buttons=int(self.spec.buttons),
            grip=grip,
        )


def press_spec(surface_z: float = 0.0, depth: float = 0.01, approach: float = 0.01, speed: float = 0.01,
               dwell: float = 0.3, **extra) -> TrajectorySpec:
    """A vertical press: start ``approach`` m above ``surface_z``, go ``depth`` m below it at
    ``speed`` m/s, hold ``dwell`` s, come back up. Extra keys (tremor, seed...) pass through."""
    if depth <= 0 or approach < 0:
        raise ConfigError(f"press depth must be > 0 m and approach >= 0 m, got depth={depth!r}, approach={approach!r}")
    top = [0.0, 0.0, surface_z + approach]
    bottom = [0.0, 0.0, surface_z - depth]
    return TrajectorySpec(waypoints=[top, bottom, top], speeds=speed, dwell=[0.05, dwell, 0.05], **extra)
