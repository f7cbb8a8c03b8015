"""The haptic servo loop: device -> proxy target, physics force -> device, at 1 kHz.

One servo tick (:meth:`ServoLoop.tick`)::

    state = device.read(t)                       # pose, buttons, grip
    no target (zero force) while a live device has no pose yet (``device.has_pose`` False)
    reject a non-finite pose (keep the last good one; count it); normalise the quaternion
    without overflow (components up to 1e308)
    clamp the position to the device workspace;  map it into the scene (scale + origin)
    publish the proxy target for the physics
    F = extrapolator.force(t, proxy target)      # physics runs at its own, slower rate
    F -> device frame (force_scale); saturate to device max_force; limit |dF| <= R h (N/s clamp)
    device.send_force(F, t)

The physics side (:meth:`ServoLoop.physics_update`) sets the latest proxy target on the physics,
steps it and hands the new ``coupling_force()`` to the extrapolator. The two sides are decoupled:

* :meth:`ServoLoop.run_simulated` runs both on a simulated clock, deterministically (tests):
  the physics updates every ``round(rate_hz / physics_rate_hz)`` ticks and steps until its clock
  reaches the servo time.
* :meth:`ServoLoop.start` / :meth:`ServoLoop.stop` run a servo thread at ``rate_hz`` (absolute
  deadlines, ``time.sleep``) and a physics thread that steps as fast as it can but never ahead of
  the wall clock. Python's GIL switch interval is lowered to 0.2 ms while they run (restored on
  stop) so the servo thread is not starved by the physics thread. Anything else touching the
  physics (a viewer, a renderer) must hold :attr:`ServoLoop.physics_lock`. The servo thread
  asks for real-time scheduling (``SCHED_FIFO``, else ``nice -10``; ``ServoStats.scheduling``
  says what it got) and sleeps to ``spin_s`` (0.2 ms) before each deadline, then polls the
  clock: see :mod:`surgsim_envs.haptics.realtime`.

Both report a :class:`ServoStats` (period median/p99, rejected poses, saturations...).
"""

from __future__ import annotations

import math
import sys
import threading
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError
from surgsim_envs.haptics.device import DeviceState, HapticDevice
from surgsim_envs.haptics.extrapolation import ForceExtrapolator, make_extrapolator
from surgsim_envs.haptics.protocol import check_physics
from surgsim_envs.haptics.quaternion import unit_quaternion
from surgsim_envs.haptics.realtime import periodic_ticks, raise_thread_priority


@dataclass
class DeviceMapping:
    """Device frame -> scene frame: ``scene = origin + position_scale * device`` (m);
    scene force -> device force: ``force_scale * F`` (N)."""

    origin: tuple = (0.0, 0.0, 0.0)
    position_scale: float = 1.0
    force_scale: float = 1.0

    def __post_init__(self) -> None:
        o = np.asarray(self.origin, dtype=float)
        if o.shape != (3,) or not np.all(np.isfinite(o)):
            raise ConfigError(f"DeviceMapping origin must be a finite (x, y, z) in m, got {self.origin!r}")
        for name in ("position_scale", "force_scale"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"DeviceMapping {name} must be > 0, got {v!r}")
        self._origin = o

    def to_scene(self, position: np.ndarray) -> np.ndarray:
        return self._origin + self.position_scale * np.asarray(position, dtype=float)

    def force_to_device(self, force: np.ndarray) -> np.ndarray:
        return self.force_scale * np.asarray(force, dtype=float)


@dataclass
class ServoConfig:
    """Servo settings. ``rate_hz`` servo rate (Hz); ``physics_rate_hz`` physics update rate in
    simulated-clock runs (Hz, ``None`` = every tick); ``max_force_rate`` N/s safety clamp on the
    change of the rendered force; ``extrapolation`` ``hold|linear|stiffness``. Threaded runs
    only: ``spin_s`` s before each tick's deadline are spent polling the clock instead of
    sleeping (0 = sleep only); ``realtime_priority`` asks for SCHED_FIFO (else nice -10) for
    the servo thread (see :mod:`surgsim_envs.haptics.realtime`)."""

    rate_hz: float = 1000.0
    physics_rate_hz: float | None = None
    max_force_rate: float = 1000.0
    extrapolation: str = "linear"
    mapping: DeviceMapping = field(default_factory=DeviceMapping)
    spin_s: float = 2e-4
    realtime_priority: bool = True

    def __post_init__(self) -> None:
        if not (math.isfinite(self.rate_hz) and 10.0 <= self.rate_hz <= 20000.0):
            raise ConfigError(f"servo rate_hz must be in [10, 20000] Hz (haptics wants 1000), got {self.rate_hz!r}")
        if self.physics_rate_hz is not None and not (math.isfinite(self.physics_rate_hz) and 0 < self.physics_rate_hz <= self.rate_hz):
            raise ConfigError(
                f"physics_rate_hz must be in (0, rate_hz={self.rate_hz}] Hz or None, got {self.physics_rate_hz!r}"
            )
        validate.positive(self.max_force_rate, "max_force_rate", unit="N/s", fix="the fastest force change sent to the device")
        make_extrapolator(self.extrapolation)  # validates the name
        if not (isinstance(self.spin_s, (int, float)) and math.isfinite(self.spin_s) and 0 <= self.spin_s < self.period):
            raise ConfigError(f"spin_s must be in [0, period={self.period:g}) s (e.g. 2e-4), got {self.spin_s!r}")

    @property
    def period(self) -> float:
        """Servo period (s)."""
        return 1.0 / self.rate_hz


@dataclass
class ServoStats:
    """Loop statistics. Periods in ms (wall clock in threaded runs, the simulated period in
    simulated runs); counts of ticks where a safety layer acted."""

    ticks: int = 0
    duration_s: float = 0.0
    rate_hz: float = 1000.0
    period_median_ms: float = float("nan")
    period_p99_ms: float = float("nan")
    period_max_ms: float = float("nan")
    period_max_at_s: float = float("nan")  # when the longest period ended, s after the first tick
    overruns: int = 0
    rejected_poses: int = 0
    workspace_clamped: int = 0
    saturated: int = 0
    rate_limited: int = 0
    physics_updates: int = 0
    physics_steps: int = 0
    physics_rate_hz: float = float("nan")
    max_force_n: float = 0.0
    simulated_clock: bool = True
    scheduling: str = "default"

    def as_dict(self) -> dict:
        return asdict(self)

    def summary(self) -> str:
        """One paragraph for the terminal."""
        clock = "simulated clock" if self.simulated_clock else "wall clock"
        return (
            f"servo: {self.ticks} ticks in {self.duration_s:.2f} s ({clock}), target {self.rate_hz:.0f} Hz; "
            f"period median {self.period_median_ms:.3f} ms, p99 {self.period_p99_ms:.3f} ms, max {self.period_max_ms:.3f} ms, "
            f"overruns (>2 periods) {self.overruns}; servo thread scheduling {self.scheduling}\n"
            f"physics: {self.physics_updates} updates, {self.physics_steps} steps, {self.physics_rate_hz:.1f} updates/s\n"
            f"safety: rejected poses {self.rejected_poses}, workspace clamps {self.workspace_clamped}, "
            f"saturated {self.saturated}, force-rate limited {self.rate_limited}; max force {self.max_force_n:.3f} N"
        )


class ServoLoop:
    """Runs a device against a physics (see module docstring)."""

    def __init__(self, device: HapticDevice, physics, config: ServoConfig | None = None,
                 extrapolator: ForceExtrapolator | None = None):
        if not isinstance(device, HapticDevice):
            raise ConfigError(f"device must be a HapticDevice, got {type(device).__name__}")
        check_physics(physics)
        self.device = device
        self.physics = physics
        self.config = config if config is not None else ServoConfig()
        self.extrapolator = extrapolator if extrapolator is not None else make_extrapolator(self.config.extrapolation)
        self.physics_lock = threading.RLock()
        self._target_lock = threading.Lock()
        self._target_pos: np.ndarray | None = None
        self._target_quat = np.array([1.0, 0.0, 0.0, 0.0])
        self._target_grip = 0.0
        self._phys_target: np.ndarray | None = None
        self.last_state: DeviceState | None = None
        self._last_good: DeviceState | None = None
        self._last_sent = np.zeros(3)
        self._periods: list[float] = []
        self.stats = ServoStats(rate_hz=self.config.rate_hz)
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._error: BaseException | None = None
        self._t0 = 0.0
        self._wall_start = 0.0

    # -- the servo side -----------------------------------------------------------------------
    @property
    def proxy_target(self) -> np.ndarray | None:
        """Latest proxy target (3,) m in scene coordinates (None before the first good pose)."""
        with self._target_lock:
            return None if self._target_pos is None else self._target_pos.copy()

    def tick(self, t: float, physics_until: float | None = None) -> np.ndarray:
        """One servo iteration at servo time ``t`` (s); returns the force sent (3,) N.

        With ``physics_until`` (simulated clock only) the physics is updated to that time right
        after the pose is read, so this tick renders the fresh sample."""
        st = self.stats
        st.ticks += 1
        state = self.device.read(t)
        self.last_state = state
        with np.errstate(over="ignore"):  # |q|^2 of a 1e300 quaternion overflows; unit_quaternion copes
            unit_q = unit_quaternion(state.quaternion) if state.is_finite() else None
        if not getattr(self.device, "has_pose", True):
            pass  # a live device before its first pose: no target, zero force
        elif unit_q is not None:
            self._last_good = state
            pos = state.position
            clamped = self.device.limits.clamp_position(pos)
            if not np.array_equal(clamped, np.asarray(pos, dtype=float)):
                st.workspace_clamped += 1
            target = self.config.mapping.to_scene(clamped)
            with self._target_lock:
                self._target_pos = target
                self._target_quat = np.array(unit_q)
                self._target_grip = float(np.clip(state.grip, 0.0, 1.0))
        else:
            st.rejected_poses += 1
        if physics_until is not None:
            self.physics_update(t, until_time=physics_until)
        target = self.proxy_target
        if target is None:
            force = np.zeros(3)
        else:
            force = self.config.mapping.force_to_device(self.extrapolator.force(t, target))
        force, saturated = self.device.limits.saturate(force)
        st.saturated += int(saturated)
        max_step = self.config.max_force_rate * self.config.period
        delta = force - self._last_sent
        dmag = float(np.linalg.norm(delta))
        if dmag > max_step:
            force = self._last_sent + delta * (max_step / dmag)
            st.rate_limited += 1
        sent = self.device.send_force(force, t)
        self._last_sent = sent
        st.max_force_n = max(st.max_force_n, float(np.linalg.norm(sent)))
        return sent

    # -- the physics side ---------------------------------------------------------------------
    def physics_update(self, t_arrival: float, until_time: float | None = None, max_steps: int = 1) -> int:
        """Set the latest proxy target, step the physics (until its clock reaches ``until_time``
        or ``max_steps`` steps when ``until_time`` is None), publish the sample stamped
        ``t_arrival`` on the servo clock. Returns the number of steps taken."""
        with self._target_lock:
            target = None if self._target_pos is None else self._target_pos.copy()
            quat, grip = self._target_quat.copy(), self._target_grip
        if target is None:
            return 0
        steps = 0
        with self.physics_lock:
            ph = self.physics
            if hasattr(ph, "set_grip"):
                ph.set_grip(grip)
            if until_time is None:
                ph.set_proxy_pose(target, quat)
                for _ in range(max_steps):
                    ph.step()
                    steps += 1
            else:
                # catch up to until_time; the proxy moves linearly from the previous update's
                # target to this one across the sub-steps (both are past servo samples: causal)
                eps = 1e-9 * max(1.0, abs(until_time))
                n = max(int(math.ceil((until_time - ph.time) / ph.dt - 1e-6)), 0)
                prev = self._phys_target if self._phys_target is not None else target
                for j in range(n):
                    ph.set_proxy_pose(prev + (j + 1) / n * (target - prev), quat)
                    ph.step()
                    steps += 1
                if n == 0:
                    ph.set_proxy_pose(target, quat)
                while ph.time < until_time - eps:  # rounding left a step
                    ph.step()
                    steps += 1
            self._phys_target = target
            force = np.asarray(ph.coupling_force(), dtype=float)
            stiffness = ph.contact_stiffness() if hasattr(ph, "contact_stiffness") else None
        self.extrapolator.update(t_arrival, force, target, stiffness)
        self.stats.physics_updates += 1
        self.stats.physics_steps += steps
        return steps

    # -- simulated clock ------------------------------------------------------------------------
    def run_simulated(self, duration: float, physics_rate_hz: float | None = None) -> ServoStats:
        """Run ``duration`` s on a simulated clock (deterministic, no threads, no sleeping)."""
        if not (math.isfinite(duration) and duration > 0):
            raise ConfigError(f"duration must be > 0 s, got {duration!r}")
        rate = physics_rate_hz if physics_rate_hz is not None else self.config.physics_rate_hz
        h = self.config.period
        ratio = 1 if rate is None else max(1, int(round(self.config.rate_hz / rate)))
        if rate is not None and abs(self.config.rate_hz / ratio - rate) > 1e-6 * rate:
            raise ConfigError(
                f"simulated physics_rate_hz={rate} must divide the servo rate {self.config.rate_hz} Hz "
                f"(e.g. {self.config.rate_hz / 4:g} Hz for every 4th tick)"
            )
        n = int(round(duration / h))
        t_phys0 = float(self.physics.time)
        for i in range(n):
            t = i * h
            self.tick(t, t_phys0 + t if i % ratio == 0 else None)
        self._periods = [h] * n
        self.stats.simulated_clock = True
        self.stats.duration_s = n * h
        self._finish_stats(physics_time=n * h)
        return self.stats

    # -- threads -------------------------------------------------------------------------------
    def start(self) -> None:
        """Start the servo and physics threads (wall clock)."""
        if self._threads:
            raise ConfigError("ServoLoop already running; call stop() first")
        self._stop.clear()
        self._error = None
        self._periods = []
        self._old_switch = sys.getswitchinterval()
        sys.setswitchinterval(2e-4)
        self._wall_start = time.perf_counter()
        self._phys_time0 = float(self.physics.time)
        self._threads = [
            threading.Thread(target=self._guard, args=(self._servo_thread,), name="haptic-servo", daemon=True),
            threading.Thread(target=self._guard, args=(self._physics_thread,), name="haptic-physics", daemon=True),
        ]
        for th in self._threads:
            th.start()

    def _guard(self, fn) -> None:
        try:
            fn()
        except BaseException as exc:  # surfaced by stop()
            self._error = exc
            self._stop.set()

    def _servo_thread(self) -> None:
        self.stats.scheduling = raise_thread_priority(self.config.realtime_priority)
        start = self._wall_start
        last = None
        for now in periodic_ticks(start, self.config.period, self.config.spin_s, self._stop.is_set):
            if last is not None:
                self._periods.append(now - last)
            last = now
            self.tick(now - start)

    def _physics_thread(self) -> None:
        start = self._wall_start
        while not self._stop.is_set():
            if self.proxy_target is None:
                time.sleep(self.config.period)
                continue
            ahead = (self.physics.time - self._phys_time0) - (time.perf_counter() - start)
            if ahead > 0:  # never run ahead of real time
                time.sleep(ahead)
                continue
            self.physics_update(time.perf_counter() - start, max_steps=1)

    @property
    def running(self) -> bool:
        return bool(self._threads)

    def stop(self) -> ServoStats:
        """Stop the threads, send zero force, return the statistics. Re-raises a thread's error."""
        self._stop.set()
        for th in self._threads:
            th.join(timeout=5.0)
        self._threads = []
        sys.setswitchinterval(getattr(self, "_old_switch", 0.005))
        elapsed = time.perf_counter() - self._wall_start
        self.stats.simulated_clock = False
        self.stats.duration_s = elapsed
        self._finish_stats(physics_time=elapsed)
        if self.device.connected:
            self.device.send_force(np.zeros(3), elapsed)
        if self._error is not None:
            raise self._error
        return self.stats

    def run_realtime(self, duration: float, on_frame=None, frame_period: float = 1 / 30) -> ServoStats:
        """Run the threads for ``duration`` s of wall clock; call ``on_frame(loop)`` every
        ``frame_period`` s (absolute deadlines; late calls are not made up) from this thread
        (viewer sync, video frames; see recording.PacedVideoWriter for a video at its rate). ``on_frame`` must hold
        ``loop.physics_lock`` while it touches the physics (briefly: copy, then render outside);
        returning False stops early."""
        return run_frames(self, duration, on_frame, frame_period, lambda: not self._stop.is_set())

    def _finish_stats(self, physics_time: float) -> None:
        st = self.stats
        p = np.asarray(self._periods, dtype=float) * 1e3
        if len(p):
            st.period_median_ms = float(np.median(p))
            st.period_p99_ms = float(np.percentile(p, 99))
            st.period_max_ms = float(np.max(p))
            st.period_max_at_s = float(np.sum(p[:int(np.argmax(p)) + 1]) * 1e-3)
            st.overruns = int(np.sum(p > 2e3 * self.config.period))
        st.physics_rate_hz = st.physics_updates / physics_time if physics_time > 0 else float("nan")


def run_frames(loop, duration: float, on_frame, frame_period: float, running) -> ServoStats:
    """The body of ``run_realtime`` shared by :class:`ServoLoop` and the process servo: check the
    arguments, ``loop.start()``, call ``on_frame(loop)`` every ``frame_period`` s on absolute deadlines
    (a slow on_frame does not stretch the period; late calls are not made up) while ``running()`` and
    for at most ``duration`` s (False from on_frame stops early), then ``loop.stop()``'s statistics."""
    if not (math.isfinite(duration) and duration > 0):
        raise ConfigError(f"duration must be > 0 s, got {duration!r}")
    if not (math.isfinite(frame_period) and frame_period > 0):
        raise ConfigError(f"frame_period must be > 0 s, got {frame_period!r}")
    loop.start()
    try:
        start = time.perf_counter()
        end = start + duration
        k = 0
        while time.perf_counter() < end and running():
            if on_frame is not None and on_frame(loop) is False:
                break
            k = max(k + 1, int((time.perf_counter() - start) / frame_period) + 1)
            time.sleep(max(0.0, min(start + k * frame_period, end) - time.perf_counter()))
    finally:
        stats = loop.stop()
    return stats
