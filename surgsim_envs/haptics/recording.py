"""Recording of the forces a (simulated) device was sent: what the hand felt.

Every :class:`~surgsim_envs.haptics.device.HapticDevice` owns a :class:`ForceLog`; the servo
writes one row per servo tick. Tests and reports read it back as arrays or a CSV file with the
header ``t,fx,fy,fz,saturated`` (s, N, N, N, 0/1).
"""

from __future__ import annotations

import csv
import threading
from pathlib import Path

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
        self._t: list[float] = []
        self._f: list[tuple[float, float, float]] = []
        self._s: list[bool] = []
        self._lock = threading.Lock()

    def append(self, t: float, force, saturated: bool = False) -> None:
        """Add one row: time ``t`` (s), ``force`` (3,) N, whether it was saturated."""
        f = np.asarray(force, dtype=float).reshape(3)
        with self._lock:
            self._t.append(float(t))
            self._f.append((float(f[0]), float(f[1]), float(f[2])))
            self._s.append(bool(saturated))
            if len(self._t) > self.max_rows:
                drop = len(self._t) - self.max_rows
                del self._t[:drop], self._f[:drop], self._s[:drop]

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
                log.append(float(row["t"]), (float(row["fx"]), float(row["fy"]), float(row["fz"])), row["saturated"] == "1")
        return log
