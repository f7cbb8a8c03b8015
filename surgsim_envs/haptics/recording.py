"""Recording of what a teleoperation session produced: the forces the hand felt, and video.

Every :class:`~surgsim_envs.haptics.device.HapticDevice` owns a :class:`ForceLog`; the servo
writes one row per servo tick. Tests and reports read it back as arrays or a CSV file with the
header ``t,fx,fy,fz,saturated`` (s, N, N, N, 0/1).

:class:`PacedVideoWriter` keeps a real-time video at its nominal frame rate: rendering competes
with the servo and physics threads and may deliver far fewer frames than ``fps`` asks (8-9
frames for a 3 s run at 25 frames/s were measured), so each rendered image is written as many
times as video frames fell due since the last one, and :meth:`PacedVideoWriter.close` pads the
video to ``duration * fps`` frames. The video then plays in real time (choppy when rendering is
slow, never fast-forwarded).
"""

from __future__ import annotations

import csv
import math
import threading
import time
from collections import deque
from pathlib import Path
from typing import Callable

import numpy as np

from surgsim_envs.errors import ConfigError

CSV_HEADER = ("t", "fx", "fy", "fz", "saturated")


class ForceLog:
    """Thread-safe append-only log of ``(t, force, saturated)`` rows.

    ``max_rows`` bounds the memory (oldest rows are dropped beyond it; default keeps one hour
    at 1 kHz).
    """

    def __init__(self, max_rows: int = 3_600_000):
        if int(max_rows) < 1:
            raise ConfigError(f"ForceLog max_rows must be >= 1, got {max_rows!r}")
        self.max_rows = int(max_rows)
        # deques with maxlen drop the oldest row in O(1): a list's del [:1] at capacity moved the
        # whole log every servo tick (36 ms per append at 3.6 M rows, after one hour at 1 kHz)
        self._t: deque = deque(maxlen=self.max_rows)
        self._f: deque = deque(maxlen=self.max_rows)
        self._s: deque = deque(maxlen=self.max_rows)
        self._lock = threading.Lock()

    def append(self, t: float, force, saturated: bool = False) -> None:
        """Add one row: time ``t`` (s), ``force`` (3,) N, whether it was saturated."""
        f = np.asarray(force, dtype=float).reshape(3)
        with self._lock:
            self._t.append(float(t))
            self._f.append((float(f[0]), float(f[1]), float(f[2])))
            self._s.append(bool(saturated))

    def __len__(self) -> int:
        return len(self._t)

    def clear(self) -> None:
        """Drop all rows."""
        with self._lock:
            self._t.clear()
            self._f.clear()
            self._s.clear()

    @property
    def times(self) -> np.ndarray:
        """(n,) s."""
        with self._lock:
            return np.array(self._t, dtype=float)

    @property
    def forces(self) -> np.ndarray:
        """(n, 3) N."""
        with self._lock:
            return np.array(self._f, dtype=float).reshape(-1, 3)

    @property
    def saturated(self) -> np.ndarray:
        """(n,) bool."""
        with self._lock:
            return np.array(self._s, dtype=bool)

    @property
    def magnitudes(self) -> np.ndarray:
        """(n,) N, force magnitudes."""
        return np.linalg.norm(self.forces, axis=1)

    def max_step(self) -> float:
        """Largest change of the force vector between consecutive rows (N)."""
        f = self.forces
        return float(np.max(np.linalg.norm(np.diff(f, axis=0), axis=1))) if len(f) > 1 else 0.0

    def to_csv(self, path) -> Path:
        """Write ``t,fx,fy,fz,saturated`` rows to ``path``; returns the path."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        t, f, s = self.times, self.forces, self.saturated
        with path.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(CSV_HEADER)
            for i in range(len(t)):
                w.writerow([f"{t[i]:.6f}", f"{f[i, 0]:.6g}", f"{f[i, 1]:.6g}", f"{f[i, 2]:.6g}", int(s[i])])
        return path

    @classmethod
    def from_csv(cls, path) -> "ForceLog":
        """Read a log written by :meth:`to_csv`."""
        path = Path(path)
        if not path.is_file():
            raise ConfigError(f"force log {str(path)!r} does not exist")
        log = cls()
        with path.open(newline="") as fh:
            reader = csv.DictReader(fh)
            missing = set(CSV_HEADER) - set(reader.fieldnames or ())
            if missing:
                raise ConfigError(f"force log {str(path)!r} lacks columns {sorted(missing)}; expected header {','.join(CSV_HEADER)}")
            for row in reader:
                try:
                    values = [float(row[k]) for k in ("t", "fx", "fy", "fz")]
                except (TypeError, ValueError):
                    raise ConfigError(f"force log {str(path)!r}, line {reader.line_num}: not four numbers "
                                      f"t,fx,fy,fz: {row!r}") from None
                if not all(math.isfinite(v) for v in values):
                    raise ConfigError(f"force log {str(path)!r}, line {reader.line_num}: non-finite value in {values}")
                log.append(values[0], values[1:], row["saturated"] == "1")
        return log


class PacedVideoWriter:
    """Wraps a frame sink (``write(image)``, ``release()``; e.g. ``cv2.VideoWriter``) so frame
    ``k`` of the video shows the newest image rendered at or before wall time ``k / fps`` after
    the first write (see module docstring). ``clock`` returns seconds (default
    ``time.perf_counter``). Frame ``k`` is written once the next image (or :meth:`close`)
    shows which image was the newest at its time, so the video lags the renders by one image."""

    def __init__(self, sink, fps: float, clock: Callable[[], float] = time.perf_counter):
        if not (isinstance(fps, (int, float)) and math.isfinite(fps) and 0 < fps <= 1000):
            raise ConfigError(f"video fps must be in (0, 1000] frames/s, got {fps!r}")
        self.sink, self.fps, self.clock = sink, float(fps), clock
        self.frames_written = 0
        self.images_rendered = 0
        self._t0: float | None = None
        self._last = None

    def _frames_before(self, now: float) -> int:
        """Number of video frames whose time ``k / fps`` lies strictly before ``now``."""
        return max(int(math.ceil((now - self._t0) * self.fps - 1e-9)), 0)

    def write(self, image) -> int:
        """Hand over the image rendered now. Frames that fell due since the previous image show
        the previous image (it was the newest then); this one shows from the next frame on.
        Returns the number of frames written by this call."""
        now = self.clock()
        n = 0
        if self._t0 is None:
            self._t0 = now
        else:
            target = self._frames_before(now)
            while self.frames_written < target:
                self.sink.write(self._last)
                self.frames_written += 1
                n += 1
        self._last = image
        self.images_rendered += 1
        return n

    def close(self, duration: float | None = None) -> None:
        """Write the frames still due with the last image, up to ``round(duration * fps)`` frames
        (if given; else up to now), then release the sink."""
        try:
            if self._last is not None:
                if duration is not None and math.isfinite(duration):
                    target = int(round(duration * self.fps))
                else:
                    target = self._frames_before(self.clock()) + 1
                while self.frames_written < target:
                    self.sink.write(self._last)
                    self.frames_written += 1
        finally:
            self.sink.release()
