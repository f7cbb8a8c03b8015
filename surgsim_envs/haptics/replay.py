"""Replay of recorded hand motion from CSV or JSON.

CSV: a header row, then one row per sample. Required columns ``t,x,y,z`` (s, m); optional
``qw,qx,qy,qz`` (unit quaternion, default identity), ``buttons`` (int bit mask, default 0),
``grip`` (in [0, 1], default 0)::

    t,x,y,z,qw,qx,qy,qz,buttons,grip
    0.000,0.0,0.0,0.020,1,0,0,0,0,0.0

JSON: ``{"version": 1, "samples": [{"t": 0.0, "position": [x, y, z], "quaternion": [w, x, y, z],
"buttons": 0, "grip": 0.0}, ...]}`` (a bare list of samples is accepted too).

Times must be strictly increasing. Between samples the position and grip are interpolated
linearly and the orientation by normalised linear interpolation (nlerp); before the first sample
and after the last the end samples are held (or the recording loops with ``loop=True``).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.haptics.device import DeviceLimits, DeviceState, HapticDevice

REPLAY_FORMAT_VERSION = 1


class ReplayDevice(HapticDevice):
    """Plays back a recorded pose stream (CSV/JSON, see module docstring)."""

    name = "replay"

    def __init__(self, path, limits: DeviceLimits | None = None, loop: bool = False, time_offset: float | None = None):
        super().__init__(limits)
        self.path = Path(path)
        self.t, self.pos, self.quat, self.buttons, self.grip = load_poses(self.path)
        self.loop = bool(loop)
        # By default the first sample plays at servo time 0.
        self.time_offset = float(self.t[0]) if time_offset is None else float(time_offset)

    @property
    def duration(self) -> float:
        """Recording length (s)."""
        return float(self.t[-1] - self.t[0])

    def _read(self, t: float) -> DeviceState:
        tr = t + self.time_offset
        if self.loop and self.duration > 0:
            tr = self.t[0] + (tr - self.t[0]) % self.duration
        tr = float(np.clip(tr, self.t[0], self.t[-1]))
        i = int(np.clip(np.searchsorted(self.t, tr, side="right") - 1, 0, len(self.t) - 1))
        j = min(i + 1, len(self.t) - 1)
        s = 0.0 if j == i else (tr - self.t[i]) / (self.t[j] - self.t[i])
        pos = self.pos[i] + s * (self.pos[j] - self.pos[i])
        qj = self.quat[j] if np.dot(self.quat[i], self.quat[j]) >= 0 else -self.quat[j]
        q = self.quat[i] + s * (qj - self.quat[i])
        q = q / np.linalg.norm(q)
        grip = float(self.grip[i] + s * (self.grip[j] - self.grip[i]))
        return DeviceState(time=t, position=pos, quaternion=q, buttons=int(self.buttons[i]), grip=grip)


def _validate(path: Path, t, pos, quat, buttons, grip):
    t = np.asarray(t, dtype=float)
    pos = np.asarray(pos, dtype=float).reshape(-1, 3)
    quat = np.asarray(quat, dtype=float).reshape(-1, 4)
    buttons = np.asarray(buttons, dtype=np.int64)
    grip = np.asarray(grip, dtype=float)
    if len(t) == 0:
        raise ConfigError(f"replay file {str(path)!r} holds no samples")
    for name, arr in (("t", t), ("position", pos), ("quaternion", quat), ("grip", grip)):
        if not np.all(np.isfinite(arr)):
            raise ConfigError(f"replay file {str(path)!r}: column '{name}' holds non-finite values; fix or drop those rows")
    if len(t) > 1 and np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0))
        raise ConfigError(f"replay file {str(path)!r}: times must increase strictly; row {k + 1} has t={t[k + 1]} after t={t[k]}")
    norms = np.linalg.norm(quat, axis=1)
    if np.any(norms < 1e-9):
        raise ConfigError(f"replay file {str(path)!r}: a quaternion has zero length; use 1,0,0,0 for no rotation")
    if np.any((grip < 0) | (grip > 1)):
        raise ConfigError(f"replay file {str(path)!r}: grip must lie in [0, 1]")
    return t, pos, quat / norms[:, None], buttons, grip


def load_poses(path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Read a CSV or JSON pose file: ``(t (n,) s, position (n,3) m, quaternion (n,4), buttons (n,), grip (n,))``."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"replay file {str(path)!r} does not exist; give a .csv or .json pose recording")
    suffix = path.suffix.lower()
    if suffix == ".json":
        try:
            data = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise ConfigError(f"replay file {str(path)!r} is not valid JSON: {exc}") from None
        if isinstance(data, dict):
            version = data.get("version", REPLAY_FORMAT_VERSION)
            if version != REPLAY_FORMAT_VERSION:
                raise ConfigError(f"replay file {str(path)!r} has version {version!r}; this build reads version {REPLAY_FORMAT_VERSION}")
            samples = data.get("samples")
        else:
            samples = data
        if not isinstance(samples, list):
            raise ConfigError(f"replay file {str(path)!r}: expected a 'samples' list of {{t, position, ...}} objects")
        try:
            t = [float(s["t"]) for s in samples]
            pos = [[float(v) for v in s["position"]] for s in samples]
            quat = [[float(v) for v in s.get("quaternion", (1, 0, 0, 0))] for s in samples]
            buttons = [int(s.get("buttons", 0)) for s in samples]
            grip = [float(s.get("grip", 0.0)) for s in samples]
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigError(f"replay file {str(path)!r}: bad sample ({exc!r}); each needs 't' (s) and 'position' [x, y, z] (m)") from None
        if any(len(p) != 3 for p in pos) or any(len(q) != 4 for q in quat):
            raise ConfigError(f"replay file {str(path)!r}: positions need 3 values and quaternions 4 (w, x, y, z)")
        return _validate(path, t, pos, quat, buttons, grip)
    if suffix == ".csv":
        with path.open(newline="") as fh:
            reader = csv.DictReader(fh)
            cols = set(reader.fieldnames or ())
            if not {"t", "x", "y", "z"} <= cols:
                raise ConfigError(f"replay CSV {str(path)!r} needs columns t,x,y,z (optional qw,qx,qy,qz,buttons,grip); found {sorted(cols)}")
            t, pos, quat, buttons, grip = [], [], [], [], []
            for lineno, row in enumerate(reader, start=2):
                try:
                    t.append(float(row["t"]))
                    pos.append([float(row["x"]), float(row["y"]), float(row["z"])])
                    if {"qw", "qx", "qy", "qz"} <= cols:
                        quat.append([float(row["qw"]), float(row["qx"]), float(row["qy"]), float(row["qz"])])
                    else:
                        quat.append([1.0, 0.0, 0.0, 0.0])
                    buttons.append(int(float(row["buttons"])) if "buttons" in cols and row["buttons"] not in ("", None) else 0)
                    grip.append(float(row["grip"]) if "grip" in cols and row["grip"] not in ("", None) else 0.0)
                except (TypeError, ValueError) as exc:
                    raise ConfigError(f"replay CSV {str(path)!r} line {lineno}: {exc}") from None
        return _validate(path, t, pos, quat, buttons, grip)
    raise ConfigError(f"replay file {str(path)!r} must end in .csv or .json")


def save_poses(path, states: list[DeviceState]) -> Path:
    """Write device states to ``path`` (.csv or .json, by suffix) in the format :func:`load_poses` reads."""
    path = Path(path)
    if not states:
        raise ConfigError("save_poses needs at least one DeviceState")
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".json":
        samples = [
            {"t": float(s.time), "position": [float(v) for v in s.position],
             "quaternion": [float(v) for v in s.quaternion], "buttons": int(s.buttons), "grip": float(s.grip)}
            for s in states
        ]
        path.write_text(json.dumps({"version": REPLAY_FORMAT_VERSION, "samples": samples}))
        return path
    if path.suffix.lower() == ".csv":
        with path.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["t", "x", "y", "z", "qw", "qx", "qy", "qz", "buttons", "grip"])
            for s in states:
                w.writerow([repr(float(s.time)), *(repr(float(v)) for v in s.position),
                            *(repr(float(v)) for v in s.quaternion), int(s.buttons), repr(float(s.grip))])
        return path
    raise ConfigError(f"save_poses: {str(path)!r} must end in .csv or .json")
