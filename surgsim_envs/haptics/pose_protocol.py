"""The wire format of the haptic pose stream: pose packets in, force packets out, over UDP.

All numbers little-endian. Every packet names the *session* it belongs to: a random 64-bit id
that a device client draws when it starts, so a restarted client is a new session and a packet
of an old session is never taken for a current one.

Pose packet (device -> simulator), 90 bytes, ``struct`` format ``<4sBBQI8dIf``:

======  =====  ========  ==================================================
offset  size   type      field
======  =====  ========  ==================================================
0       4      bytes     magic ``b"SSHP"``
4       1      uint8     version (``2``)
5       1      uint8     type ``1`` (pose)
6       8      uint64    session id (random, drawn by the device client at start)
14      4      uint32    sequence number (wraps; newer = larger modulo 2^32)
18      8      float64   timestamp, s (sender clock)
26      24     3 x f64   position, m (device frame)
50      32     4 x f64   orientation quaternion ``w, x, y, z``
82      4      uint32    buttons bit mask
86      4      float32   grip in [0, 1]
======  =====  ========  ==================================================

Force packet (simulator -> device), 51 bytes, ``<4sBBQIddddB``: magic, version, type ``2``,
session id (that of the pose stream it answers), sequence, timestamp (s, servo clock), force x,
y, z (N, on the hand, already limited), flags (bit 0: saturated).

Authenticated packets
---------------------
With a key (a per-session secret of at least 16 bytes shared by the simulator and the device),
every packet is followed by a 32-byte tag, ``HMAC-SHA256(key, packet bytes before the tag)``:
pose packets are 122 bytes and force packets 83. A side holding a key refuses untagged packets
and packets whose tag does not verify; a side without a key refuses tagged ones. The simulator
requires a key whenever it binds an interface other than loopback.

Version 1 (82-byte poses without a session id) is no longer accepted: a version-1 sender gets
its packets counted as malformed ("protocol version 1 not supported").
"""

from __future__ import annotations

import hashlib
import hmac
import math
import secrets
import struct
from dataclasses import dataclass

from surgsim_envs.errors import ConfigError
from surgsim_envs.haptics.quaternion import unit_quaternion

MAGIC = b"SSHP"
PROTOCOL_VERSION = 2
TYPE_POSE, TYPE_FORCE = 1, 2
POSE_STRUCT = struct.Struct("<4sBBQI8dIf")
FORCE_STRUCT = struct.Struct("<4sBBQIddddB")
TAG_SIZE = 32
POSE_SIZE, FORCE_SIZE = POSE_STRUCT.size, FORCE_STRUCT.size  # 90, 51
#: the shortest key accepted (bytes); new_session_key() draws 32
MIN_KEY_BYTES = 16


class MalformedPacketError(ConfigError):
    """A datagram that is not a valid packet of this protocol."""


@dataclass(frozen=True)
class PosePacket:
    session: int
    seq: int
    timestamp: float
    position: tuple
    quaternion: tuple
    buttons: int
    grip: float


@dataclass(frozen=True)
class ForcePacket:
    session: int
    seq: int
    timestamp: float
    force: tuple
    saturated: bool


def new_session_key() -> bytes:
    """A fresh random 32-byte secret for one teleoperation session."""
    return secrets.token_bytes(32)


def new_session_id() -> int:
    """A fresh random 64-bit session id (what a device client sends in every packet)."""
    return secrets.randbits(64)


def check_key(key) -> bytes | None:
    """``key`` as bytes (None stays None); a hex string is accepted. Raises ConfigError."""
    if key is None:
        return None
    if isinstance(key, str):
        try:
            key = bytes.fromhex(key)
        except ValueError:
            raise ConfigError(f"pose stream key {key[:12]!r}... is not hex; pass bytes or a hex string "
                              "(e.g. surgsim_envs.haptics.udp_bridge.new_session_key().hex())") from None
    if not isinstance(key, (bytes, bytearray)) or len(key) < MIN_KEY_BYTES:
        got = f"{len(key)} bytes" if isinstance(key, (bytes, bytearray)) else type(key).__name__
        raise ConfigError(f"pose stream key must be at least {MIN_KEY_BYTES} random bytes, got {got}; "
                          "draw one with new_session_key()")
    return bytes(key)


def _tag(key: bytes, body: bytes) -> bytes:
    return hmac.new(key, body, hashlib.sha256).digest()


def _seal(body: bytes, key: bytes | None) -> bytes:
    return body if key is None else body + _tag(key, body)


def _open(data, size: int, key: bytes | None, what: str) -> bytes:
    """The packet body of ``data`` after its length and tag are checked."""
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise MalformedPacketError(f"{what} packet must be bytes, got {type(data).__name__}")
    data = bytes(data)
    want = size + (TAG_SIZE if key is not None else 0)
    if len(data) != want:
        if key is None and len(data) == size + TAG_SIZE:
            raise MalformedPacketError(f"{what} packet carries an authentication tag but no key is set")
        if key is not None and len(data) == size:
            raise MalformedPacketError(f"{what} packet carries no authentication tag (a key is required)")
        raise MalformedPacketError(f"{what} packet must be {want} bytes, got {len(data)}")
    if key is None:
        return data
    body, tag = data[:size], data[size:]
    if not hmac.compare_digest(tag, _tag(key, body)):
        raise MalformedPacketError(f"{what} packet authentication tag does not verify")
    return body


def _check_header(body: bytes, st: struct.Struct, ptype: int, what: str) -> tuple:
    fields = st.unpack(body)
    if fields[0] != MAGIC:
        raise MalformedPacketError(f"bad magic {fields[0]!r}, expected {MAGIC!r}")
    if fields[1] != PROTOCOL_VERSION:
        raise MalformedPacketError(f"protocol version {fields[1]} not supported (this build speaks {PROTOCOL_VERSION})")
    if fields[2] != ptype:
        raise MalformedPacketError(f"packet type {fields[2]}, expected {ptype} ({what})")
    return fields


def encode_pose(seq: int, timestamp: float, position, quaternion=(1.0, 0.0, 0.0, 0.0), buttons: int = 0,
                grip: float = 0.0, session: int = 0, key: bytes | None = None) -> bytes:
    """Pack a pose packet, tagged when ``key`` is given (no validation of finiteness: senders
    may test rejection)."""
    p = [float(v) for v in position]
    q = [float(v) for v in quaternion]
    if len(p) != 3 or len(q) != 4:
        raise ConfigError(f"pose needs 3 position and 4 quaternion values, got {len(p)} and {len(q)}")
    body = POSE_STRUCT.pack(MAGIC, PROTOCOL_VERSION, TYPE_POSE, int(session) & 0xFFFFFFFFFFFFFFFF,
                            int(seq) & 0xFFFFFFFF, float(timestamp), *p, *q, int(buttons) & 0xFFFFFFFF, float(grip))
    return _seal(body, check_key(key))


def decode_pose(data: bytes, key: bytes | None = None) -> PosePacket:
    """Unpack and validate a pose packet (its tag too when ``key`` is given); raises
    :class:`MalformedPacketError`."""
    f = _check_header(_open(data, POSE_SIZE, key, "pose"), POSE_STRUCT, TYPE_POSE, "pose")
    session, seq, ts, pos, quat, buttons, grip = f[3], f[4], f[5], f[6:9], f[9:13], f[13], f[14]
    nums = (ts, *pos, *quat, grip)
    if not all(math.isfinite(v) for v in nums):
        raise MalformedPacketError(f"pose packet holds a non-finite number: {nums}")
    unit = unit_quaternion(quat)
    if unit is None:
        raise MalformedPacketError(f"pose quaternion {tuple(quat)} has zero length")
    if not (0.0 <= grip <= 1.0):
        raise MalformedPacketError(f"grip {grip} outside [0, 1]")
    return PosePacket(session, seq, ts, tuple(pos), unit, buttons, grip)


def encode_force(seq: int, timestamp: float, force, saturated: bool = False, session: int = 0,
                 key: bytes | None = None) -> bytes:
    """Pack a force packet, tagged when ``key`` is given."""
    f = [float(v) for v in force]
    if len(f) != 3:
        raise ConfigError(f"force needs 3 values (N), got {len(f)}")
    body = FORCE_STRUCT.pack(MAGIC, PROTOCOL_VERSION, TYPE_FORCE, int(session) & 0xFFFFFFFFFFFFFFFF,
                             int(seq) & 0xFFFFFFFF, float(timestamp), *f, 1 if saturated else 0)
    return _seal(body, check_key(key))


def decode_force(data: bytes, key: bytes | None = None) -> ForcePacket:
    """Unpack and validate a force packet (its tag too when ``key`` is given); raises
    :class:`MalformedPacketError`."""
    f = _check_header(_open(data, FORCE_SIZE, key, "force"), FORCE_STRUCT, TYPE_FORCE, "force")
    if not all(math.isfinite(v) for v in f[5:9]):
        raise MalformedPacketError("force packet holds a non-finite number")
    return ForcePacket(f[3], f[4], f[5], tuple(f[6:9]), bool(f[9] & 1))
