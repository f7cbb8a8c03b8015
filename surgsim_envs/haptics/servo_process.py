"""The 1 kHz servo in its own process: no GIL shared with the physics.

In :class:`~surgsim_envs.haptics.servo.ServoLoop` the servo and physics threads share one GIL.
A physics step that holds it (a numba kernel without ``nogil``, a long numpy expression) delays
the servo by its whole duration, and every socket call of the servo (each ``recvfrom`` of a
flood) gives the GIL away and may wait a whole switch interval to get it back. Here the servo
runs the same :meth:`ServoLoop.tick` in a child process (spawned) that owns the device; the
physics stays in this process and steps in a thread as fast as the wall clock allows. They
exchange two small fixed records through shared memory, each written by one side under a
sequence lock (the writer makes the counter odd, writes, makes it even; a reader retries while
it is odd or changed):

* *target* (servo -> physics): proxy position (3) m, quaternion (4), grip, valid flag;
* *sample* (physics -> servo): arrival time on the servo clock (s), coupling force (3) N, the
  target it was computed for (3) m, contact stiffness N/m (NaN: none) - fed to the servo's
  force extrapolator exactly as the threaded loop does.

Both clocks are ``time.perf_counter`` (``CLOCK_MONOTONIC``, the same in every process on Linux)
from one start instant. The device is built in the child by ``device_factory`` (a picklable
callable, e.g. ``functools.partial(UdpDevice, port=0)``); its bound address and its ``stats``
come back through a pipe. The child asks for real-time scheduling like the threaded loop
(:mod:`surgsim_envs.haptics.realtime`); it stops by itself within ~0.3 s if the parent process
dies (even by SIGKILL), sending zero force. Use it for live devices whose servo must keep 1 kHz
whatever the physics does; simulated-clock runs stay with :class:`ServoLoop`.
"""

from __future__ import annotations

import math
import multiprocessing as mp
import os
import threading
import time
from dataclasses import asdict, is_dataclass

import numpy as np

from surgsim_envs.errors import ConfigError, SurgSimError
from surgsim_envs.haptics.protocol import check_physics
from surgsim_envs.haptics.realtime import periodic_ticks, raise_thread_priority
from surgsim_envs.haptics.recording import ForceLog
from surgsim_envs.haptics.servo import ServoConfig, ServoLoop, ServoStats, run_frames

TARGET_SIZE = 9  # valid, x, y, z, qw, qx, qy, qz, grip
SAMPLE_SIZE = 8  # t_arrival, fx, fy, fz, target x, y, z, stiffness (NaN = none)


class ServoProcessError(SurgSimError, RuntimeError):
    """The servo child process failed (its traceback is in the message)."""


class SeqLockRecord:
    """A fixed-size record of doubles in shared memory, one writer, any readers."""

    def __init__(self, size: int, ctx=None):
        ctx = ctx if ctx is not None else mp.get_context("spawn")
        self.size = int(size)
        self.buf = ctx.RawArray("d", self.size + 1)  # [0] is the sequence counter

    def write(self, values) -> None:
        b = self.buf
        b[0] += 1.0  # odd: writing
        b[1:self.size + 1] = values
        b[0] += 1.0  # even: consistent

    def read(self, tries: int = 1000) -> tuple[int | None, list | None]:
        """``(sequence, values)``; sequence 0 means never written. ``(None, None)`` when no
        consistent copy was had in ``tries`` attempts (a writer preempted mid-write, or killed
        mid-write: the record then stays odd for ever, and a reader must not wait for it)."""
        b = self.buf
        for _ in range(tries):
            s0 = b[0]
            if int(s0) % 2 == 0:
                vals = b[1:self.size + 1]
                if b[0] == s0:
                    return int(s0), vals
            time.sleep(0)
        return None, None


class _NoPhysics:
    """Stands in for the physics inside the servo process (only ticks run there)."""

    dt, time = 1e-3, 0.0

    def set_proxy_pose(self, position, quaternion) -> None:
        pass

    def step(self) -> None:
        pass

    def coupling_force(self) -> np.ndarray:
        return np.zeros(3)


def _servo_main(device_factory, config: ServoConfig, go, target: SeqLockRecord, sample: SeqLockRecord,
                stop, conn) -> None:  # runs in the child process
    """Build the device, report ready, wait for the parent's start instant ``go``, run the ticks."""
    import traceback

    parent = mp.parent_process().pid  # the spawning process (os.getppid() would race with its death)
    try:
        device = device_factory()
        device.connect()
        try:
            loop = ServoLoop(device, _NoPhysics(), config)
            address = getattr(device, "address", None) if hasattr(type(device), "address") else None
            conn.send(("ready", address))
            while math.isnan(go.value) and not stop.value:  # spawning took ~1 s: the clock starts now
                if os.getppid() != parent:
                    return
                time.sleep(1e-3)
            start = go.value
            scheduling = raise_thread_priority(config.realtime_priority)
            periods: list[float] = []
            last, seen, ticks = None, 0, [0]

            def should_stop() -> bool:
                ticks[0] += 1          # every 256 ticks: has the parent died (killed)? stop, do not linger
                return bool(stop.value) or (ticks[0] % 256 == 1 and os.getppid() != parent)

            for now in periodic_ticks(start, config.period, config.spin_s, should_stop):
                if last is not None:
                    periods.append(now - last)
                last = now
                seq, s = sample.read()
                if seq is not None and seq != seen:  # None: the physics is mid-write (or dead); keep the last
                    seen = seq
                    loop.extrapolator.update(s[0], s[1:4], s[4:7], None if math.isnan(s[7]) else s[7])
                    loop.stats.physics_updates += 1
                loop.tick(now - start)
                if loop._target_pos is not None:
                    target.write([1.0, *loop._target_pos, *loop._target_quat, loop._target_grip])
            elapsed = time.perf_counter() - start
            loop._periods = periods
            loop.stats.simulated_clock = False
            loop.stats.duration_s = elapsed
            loop.stats.scheduling = scheduling
            loop._finish_stats(physics_time=elapsed)
            device.send_force(np.zeros(3), elapsed)
            dstats = asdict(device.stats) if is_dataclass(getattr(device, "stats", None)) else {}
            log = device.force_log
            conn.send(("stats", loop.stats.as_dict(), dstats, (log.times, log.forces, log.saturated)))
        finally:
            device.close()
    except BaseException:  # noqa: BLE001 - reported to the parent, which raises it
        try:
            conn.send(("error", traceback.format_exc()))
        except OSError:  # the parent is gone
            pass


class ProcessServoLoop:
    """The servo in a child process, the physics in a thread of this one (module docstring).

    ``start()`` / ``stop()`` or ``run_realtime(duration)``; after ``start()``
    :attr:`device_address` is the device's bound address (None for devices without one); after
    ``stop()`` :attr:`stats` is the servo's :class:`ServoStats` (physics counts from this
    process), :attr:`device_stats` the device's statistics as a dict and :attr:`force_log` the
    forces the device rendered (a :class:`ForceLog`)."""

    def __init__(self, device_factory, physics, config: ServoConfig | None = None, start_timeout: float = 60.0):
        if not callable(device_factory):
            raise ConfigError(f"device_factory must be a picklable callable returning a HapticDevice, got {device_factory!r}")
        check_physics(physics)
        if not (math.isfinite(start_timeout) and start_timeout > 0):
            raise ConfigError(f"start_timeout must be > 0 s, got {start_timeout!r}")
        self.device_factory = device_factory
        self.physics = physics
        self.config = config if config is not None else ServoConfig()
        self.start_timeout = float(start_timeout)
        self.physics_lock = threading.RLock()
        self.stats = ServoStats(rate_hz=self.config.rate_hz)
        self.device_stats: dict = {}
        self.force_log = ForceLog()
        self.device_address = None
        self._proc = None
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self._stop_physics = threading.Event()

    @property
    def running(self) -> bool:
        return self._proc is not None

    def start(self) -> None:
        if self._proc is not None:
            raise ConfigError("ProcessServoLoop already running; call stop() first")
        ctx = mp.get_context("spawn")
        self._target = SeqLockRecord(TARGET_SIZE, ctx)
        self._sample = SeqLockRecord(SAMPLE_SIZE, ctx)
        self._stop_flag = ctx.RawValue("b", 0)
        self._conn, child_conn = ctx.Pipe(duplex=False)
        self._phys_time0 = float(self.physics.time)
        self._physics_updates = self._physics_steps = 0
        go = ctx.RawValue("d", math.nan)  # the start instant, set once the child is up
        self._proc = ctx.Process(target=_servo_main, name="haptic-servo",
                                 args=(self.device_factory, self.config, go, self._target, self._sample,
                                       self._stop_flag, child_conn), daemon=True)
        self._proc.start()
        child_conn.close()
        if not self._conn.poll(self.start_timeout):
            self._kill()
            raise ServoProcessError(f"the servo process did not start within {self.start_timeout} s")
        msg = self._receive()
        if msg[0] == "error":
            self._kill()
            raise ServoProcessError(f"the servo process failed to start:\n{msg[1]}")
        self.device_address = msg[1]
        self._start = time.perf_counter()
        go.value = self._start
        self._stop_physics.clear()
        self._error = None
        self._thread = threading.Thread(target=self._guard, name="haptic-physics", daemon=True)
        self._thread.start()

    def _receive(self) -> tuple:
        try:
            return self._conn.recv()
        except (EOFError, OSError):  # the child died without a word
            self._proc.join(timeout=5.0)
            return ("error", f"the servo process exited with code {self._proc.exitcode} without reporting; a "
                             "script that starts it must guard its code with `if __name__ == '__main__':` "
                             "(the child is spawned and imports the script)")

    def _kill(self) -> None:
        if self._proc is not None:
            self._proc.kill()
            self._proc.join(timeout=5.0)
            self._proc = None

    def _guard(self) -> None:
        try:
            self._physics_thread()
        except BaseException as exc:  # surfaced by stop()
            self._error = exc
            self._stop_physics.set()

    def _physics_thread(self) -> None:
        ph, start = self.physics, self._start
        while not self._stop_physics.is_set():
            seq, t = self._target.read()
            if not seq or t[0] != 1.0:  # no pose yet (or the servo is mid-write / gone)
                time.sleep(self.config.period)
                continue
            ahead = (ph.time - self._phys_time0) - (time.perf_counter() - start)
            if ahead > 0:  # never run ahead of real time
                time.sleep(ahead)
                continue
            pos, quat, grip = np.array(t[1:4]), np.array(t[4:8]), t[8]
            t_arrival = time.perf_counter() - start  # as ServoLoop.physics_update stamps it
            with self.physics_lock:
                if hasattr(ph, "set_grip"):
                    ph.set_grip(grip)
                ph.set_proxy_pose(pos, quat)
                ph.step()
                force = np.asarray(ph.coupling_force(), dtype=float)
                k = ph.contact_stiffness() if hasattr(ph, "contact_stiffness") else None
            self._sample.write([t_arrival, *force, *pos, math.nan if k is None else float(k)])
            self._physics_updates += 1
            self._physics_steps += 1

    def stop(self) -> ServoStats:
        """Stop both sides; returns the statistics. Raises the physics thread's error or
        :class:`ServoProcessError` for the child's."""
        if self._proc is None:
            raise ConfigError("ProcessServoLoop is not running; call start() first")
        self._stop_flag.value = 1
        self._stop_physics.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        msg = self._receive() if self._conn.poll(10.0) else ("error", "no statistics within 10 s of stop")
        self._proc.join(timeout=5.0)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join(timeout=5.0)
        self._proc = None
        self._conn.close()
        if msg[0] == "error":
            raise ServoProcessError(f"the servo process failed:\n{msg[1]}")
        self.stats = ServoStats(**msg[1])
        self.device_stats = msg[2]
        self.force_log = ForceLog(max_rows=max(1, len(msg[3][0])))
        for t, f, sat in zip(*msg[3]):
            self.force_log.append(t, f, bool(sat))
        elapsed = time.perf_counter() - self._start
        self.stats.physics_updates = self._physics_updates
        self.stats.physics_steps = self._physics_steps
        self.stats.physics_rate_hz = self._physics_updates / elapsed if elapsed > 0 else math.nan
        if self._error is not None:
            raise self._error
        return self.stats

    def run_realtime(self, duration: float, on_frame=None, frame_period: float = 1 / 30) -> ServoStats:
        """Run for ``duration`` s of wall clock, calling ``on_frame(loop)`` every ``frame_period``
        s from this thread as :meth:`ServoLoop.run_realtime` does (hold ``loop.physics_lock``
        while touching the physics; returning False stops early); returns the statistics."""
        return run_frames(self, duration, on_frame, frame_period,
                          lambda: not self._stop_physics.is_set() and self._proc.is_alive())
