"""A network bridge for remote haptic devices: pose packets in, force packets out, over UDP.

By default the simulator binds ``127.0.0.1`` (loopback only; pass another host deliberately to
accept poses from the network — there is no authentication). All numbers little-endian.

Pose packet (device -> simulator), 82 bytes, ``struct`` format ``<4sBBI8dIf``:

======  =====  ========  ==================================================
offset  size   type      field
======  =====  ========  ==================================================
0       4      bytes     magic ``b"SSHP"``
4       1      uint8     version (``1``)
5       1      uint8     type ``1`` (pose)
6       4      uint32    sequence number (wraps; newer = larger modulo 2^32)
10      8      float64   timestamp, s (sender clock)
18      24     3 x f64   position, m (device frame)
42      32     4 x f64   orientation quaternion ``w, x, y, z``
74      4      uint32    buttons bit mask
78      4      float32   grip in [0, 1]
======  =====  ========  ==================================================

Force packet (simulator -> device), 43 bytes, ``<4sBBIddddB``: magic, version, type ``2``,
sequence, timestamp (s, servo clock), force x, y, z (N, on the hand, already limited), flags
(bit 0: saturated).

A datagram is *malformed* (counted in ``stats.malformed`` and dropped; the bridge never raises
for it) when its length, magic, version or type is wrong, a number is non-finite, the quaternion
has zero length (after scaling by its largest component, so ``1e300`` components that overflow
when squared are still normalised correctly) or grip is outside [0, 1]. A decoded quaternion is
always unit length. Forces go back to the address of the last valid pose packet.

Sequence window and session restart
-----------------------------------
A pose is *in window* when its sequence number is ahead of the last accepted one by 1 to
:data:`SEQ_WINDOW` (65,536, about 65 s of packets at 1 kHz) modulo 2^32; only in-window poses are
applied. Every other valid pose (older, repeated, or far ahead) is counted in ``stats.stale`` and
dropped, so one stray packet with a far-ahead number cannot lock genuine packets out.
A *session restart* (a device client that restarts at sequence 0, or jumps) is adopted when
either

* :data:`RESYNC_PACKETS` (3) consecutive out-of-window poses arrive from one address, each in
  window of the one before (a live, counting stream), with no in-window pose between them; or
* no pose was accepted for :data:`SESSION_TIMEOUT_S` (0.5 s): the next valid pose starts a new
  session whatever its number.

Restarts are counted in ``stats.resyncs``.

Flooding
--------
One :meth:`UdpDevice.poll` (once per servo tick) reads at most ``max_drain`` datagrams
(default 32) and stops after ``max_poll_s`` (default 0.2 ms) of wall clock, so a flood of
garbage cannot starve the 1 kHz servo; the rest stays queued in the kernel (which drops what
overflows its buffer). Datagrams of the wrong length are rejected before any decoding.

Trust model
-----------
The bridge has no authentication and no encryption: any process that can reach the port can
move the proxy. It binds loopback (``127.0.0.1``) by default; bind another interface only on a
network you trust. Until the first valid pose arrives the device reports *no pose*
(:attr:`UdpDevice.has_pose` is False) and the servo renders zero force.
"""

from __future__ import annotations

import math
import socket
import struct
import time
from dataclasses import dataclass

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.haptics.device import DeviceLimits, DeviceState, HapticDevice
from surgsim_envs.haptics.quaternion import unit_quaternion

MAGIC = b"SSHP"
PROTOCOL_VERSION = 1
TYPE_POSE, TYPE_FORCE = 1, 2
POSE_STRUCT = struct.Struct("<4sBBI8dIf")
FORCE_STRUCT = struct.Struct("<4sBBIddddB")
POSE_SIZE, FORCE_SIZE = POSE_STRUCT.size, FORCE_STRUCT.size  # 82, 43
DEFAULT_HOST = "127.0.0.1"
#: poses ahead of the last accepted one by 1..SEQ_WINDOW (mod 2^32) are applied
SEQ_WINDOW = 1 << 16
#: consecutive counting out-of-window poses from one address that restart the session
RESYNC_PACKETS = 3
#: a pose arriving after this long without an accepted pose starts a new session (s)
SESSION_TIMEOUT_S = 0.5


class MalformedPacketError(ConfigError):
    """A datagram that is not a valid packet of this protocol."""


@dataclass(frozen=True)
class PosePacket:
    seq: int
    timestamp: float
    position: tuple
    quaternion: tuple
    buttons: int
    grip: float


@dataclass(frozen=True)
class ForcePacket:
    seq: int
    timestamp: float
    force: tuple
    saturated: bool


def encode_pose(seq: int, timestamp: float, position, quaternion=(1.0, 0.0, 0.0, 0.0), buttons: int = 0,
                grip: float = 0.0) -> bytes:
    """Pack a pose packet (no validation of finiteness: senders may test rejection)."""
    p = [float(v) for v in position]
    q = [float(v) for v in quaternion]
    if len(p) != 3 or len(q) != 4:
        raise ConfigError(f"pose needs 3 position and 4 quaternion values, got {len(p)} and {len(q)}")
    return POSE_STRUCT.pack(MAGIC, PROTOCOL_VERSION, TYPE_POSE, int(seq) & 0xFFFFFFFF, float(timestamp), *p, *q,
                            int(buttons) & 0xFFFFFFFF, float(grip))


def _check_header(data: bytes, size: int, ptype: int, what: str) -> tuple:
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise MalformedPacketError(f"{what} packet must be bytes, got {type(data).__name__}")
    if len(data) != size:
        raise MalformedPacketError(f"{what} packet must be {size} bytes, got {len(data)}")
    st = POSE_STRUCT if ptype == TYPE_POSE else FORCE_STRUCT
    fields = st.unpack(bytes(data))
    if fields[0] != MAGIC:
        raise MalformedPacketError(f"bad magic {fields[0]!r}, expected {MAGIC!r}")
    if fields[1] != PROTOCOL_VERSION:
        raise MalformedPacketError(f"protocol version {fields[1]} not supported (this build speaks {PROTOCOL_VERSION})")
    if fields[2] != ptype:
        raise MalformedPacketError(f"packet type {fields[2]}, expected {ptype} ({what})")
    return fields


def decode_pose(data: bytes) -> PosePacket:
    """Unpack and validate a pose packet; raises :class:`MalformedPacketError`."""
    f = _check_header(data, POSE_SIZE, TYPE_POSE, "pose")
    seq, ts, pos, quat, buttons, grip = f[3], f[4], f[5:8], f[8:12], f[12], f[13]
    nums = (ts, *pos, *quat, grip)
    if not all(math.isfinite(v) for v in nums):
        raise MalformedPacketError(f"pose packet holds a non-finite number: {nums}")
    unit = unit_quaternion(quat)
    if unit is None:
        raise MalformedPacketError(f"pose quaternion {tuple(quat)} has zero length")
    if not (0.0 <= grip <= 1.0):
        raise MalformedPacketError(f"grip {grip} outside [0, 1]")
    return PosePacket(seq, ts, tuple(pos), unit, buttons, grip)


def encode_force(seq: int, timestamp: float, force, saturated: bool = False) -> bytes:
    """Pack a force packet."""
    f = [float(v) for v in force]
    if len(f) != 3:
        raise ConfigError(f"force needs 3 values (N), got {len(f)}")
    return FORCE_STRUCT.pack(MAGIC, PROTOCOL_VERSION, TYPE_FORCE, int(seq) & 0xFFFFFFFF, float(timestamp), *f,
                             1 if saturated else 0)


def decode_force(data: bytes) -> ForcePacket:
    """Unpack and validate a force packet; raises :class:`MalformedPacketError`."""
    f = _check_header(data, FORCE_SIZE, TYPE_FORCE, "force")
    if not all(math.isfinite(v) for v in f[4:8]):
        raise MalformedPacketError("force packet holds a non-finite number")
    return ForcePacket(f[3], f[4], tuple(f[5:8]), bool(f[8] & 1))


class SequenceGate:
    """The sequence window and session-restart rule of the module docstring (no I/O, testable).

    ``admit(seq, addr, now)`` returns True when the pose must be applied (and records it)."""

    def __init__(self, window: int = SEQ_WINDOW, resync_packets: int = RESYNC_PACKETS,
                 session_timeout: float = SESSION_TIMEOUT_S):
        self.window, self.resync_packets, self.session_timeout = int(window), int(resync_packets), float(session_timeout)
        self.last_seq: int | None = None
        self.last_time = -math.inf
        self.resyncs = 0
        self._run_addr = None
        self._run_seq: int | None = None
        self._run_len = 0

    def _in_window(self, seq: int, ref: int | None) -> bool:
        return ref is None or 0 < ((seq - ref) & 0xFFFFFFFF) <= self.window

    def admit(self, seq: int, addr, now: float) -> bool:
        restart = False
        if self.last_seq is not None and now - self.last_time > self.session_timeout:
            restart = True
        elif not self._in_window(seq, self.last_seq):
            if self._run_len and addr == self._run_addr and self._in_window(seq, self._run_seq):
                self._run_len += 1
            else:
                self._run_len = 1
            self._run_addr, self._run_seq = addr, seq
            if self._run_len < self.resync_packets:
                return False
            restart = True
        if restart:
            self.resyncs += 1
        self.last_seq, self.last_time = seq, now
        self._run_len, self._run_seq, self._run_addr = 0, None, None
        return True


@dataclass
class BridgeStats:
    received: int = 0
    accepted: int = 0
    malformed: int = 0
    stale: int = 0
    resyncs: int = 0
    polls_truncated: int = 0
    forces_sent: int = 0
    send_errors: int = 0


def _check_endpoint(host: str, port: int) -> None:
    if not isinstance(host, str) or not host:
        raise ConfigError(f"host must be an IP address string such as '127.0.0.1', got {host!r}")
    if not isinstance(port, int) or not (0 <= port <= 65535):
        raise ConfigError(f"UDP port must be an integer in [0, 65535] (0 = any free port), got {port!r}")


class UdpDevice(HapticDevice):
    """Simulator side: receives pose packets on ``host:port``, sends force packets back.

    ``read`` drains queued datagrams without blocking (at most ``max_drain`` datagrams and
    ``max_poll_s`` s per call) and returns the newest valid pose (the handle stays where it was
    if nothing new arrived). Before the first pose it reports the workspace centre with
    :attr:`has_pose` False; the servo renders zero force until a pose arrives. ``port=0`` binds
    a free port: see :attr:`address` after ``connect()``.
    """

    name = "udp"

    def __init__(self, port: int = 0, host: str = DEFAULT_HOST, limits: DeviceLimits | None = None,
                 max_drain: int = 32, max_poll_s: float = 2e-4):
        super().__init__(limits)
        _check_endpoint(host, port)
        if not (isinstance(max_drain, int) and max_drain >= 1):
            raise ConfigError(f"max_drain must be an integer >= 1 datagram per poll, got {max_drain!r}")
        if not (isinstance(max_poll_s, (int, float)) and math.isfinite(max_poll_s) and max_poll_s > 0):
            raise ConfigError(f"max_poll_s must be a positive time budget in s (e.g. 2e-4), got {max_poll_s!r}")
        self.host, self.port = host, port
        self.max_drain = int(max_drain)
        self.max_poll_s = float(max_poll_s)
        self.stats = BridgeStats()
        self._sock: socket.socket | None = None
        self._peer = None
        self._gate = SequenceGate()
        self._seq_out = 0
        centre = 0.5 * (np.asarray(self.limits.workspace_min) + np.asarray(self.limits.workspace_max))
        self._state = DeviceState(time=0.0, position=centre, quaternion=np.array([1.0, 0.0, 0.0, 0.0]))
        self.last_packet: PosePacket | None = None

    @property
    def address(self) -> tuple[str, int]:
        """Bound ``(host, port)``."""
        if self._sock is None:
            raise ConfigError("UdpDevice is not connected; call connect() first")
        return self._sock.getsockname()[:2]

    def _connect(self) -> None:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((self.host, self.port))
        except OSError as exc:
            sock.close()
            raise ConfigError(f"cannot bind UDP {self.host}:{self.port} ({exc}); choose another port or 0 for any") from None
        sock.setblocking(False)
        self._sock = sock

    def _close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    @property
    def has_pose(self) -> bool:
        """True once a valid pose has been accepted."""
        return self.last_packet is not None

    def poll(self) -> int:
        """Read queued datagrams (bounded: ``max_drain`` datagrams, ``max_poll_s`` s); returns
        how many valid poses were accepted."""
        if self._sock is None:
            return 0
        accepted = 0
        deadline = time.perf_counter() + self.max_poll_s
        for i in range(self.max_drain):
            if i and time.perf_counter() > deadline:
                self.stats.polls_truncated += 1
                break
            try:
                data, addr = self._sock.recvfrom(2048)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # e.g. ICMP port unreachable reported on a later recv
                continue
            self.stats.received += 1
            if len(data) != POSE_SIZE:
                self.stats.malformed += 1
                continue
            try:
                pkt = decode_pose(data)
            except MalformedPacketError:
                self.stats.malformed += 1
                continue
            resyncs = self._gate.resyncs
            if not self._gate.admit(pkt.seq, addr, time.monotonic()):
                self.stats.stale += 1
                continue
            self.stats.resyncs += self._gate.resyncs - resyncs
            self._peer = addr
            self.last_packet = pkt
            self._state = DeviceState(time=pkt.timestamp, position=np.array(pkt.position),
                                      quaternion=np.array(pkt.quaternion), buttons=pkt.buttons, grip=pkt.grip)
            self.stats.accepted += 1
            accepted += 1
        return accepted

    def _read(self, t: float) -> DeviceState:
        self.poll()
        return self._state

    def _render(self, force: np.ndarray, t: float) -> None:
        if self._peer is None or self._sock is None:
            return
        try:
            packet = encode_force(self._seq_out, t if math.isfinite(t) else 0.0, force, self.last_saturated)
            self._sock.sendto(packet, self._peer)
            self._seq_out += 1
            self.stats.forces_sent += 1
        except OSError:
            self.stats.send_errors += 1


class UdpHapticClient:
    """Device side (a remote hand, or a test): sends pose packets, receives force packets.

    Use as a context manager; sockets are always closed on exit."""

    def __init__(self, server: tuple[str, int], host: str = DEFAULT_HOST, port: int = 0):
        _check_endpoint(host, port)
        _check_endpoint(server[0], server[1])
        self.server = (server[0], int(server[1]))
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((host, port))
        except OSError as exc:
            self._sock.close()
            raise ConfigError(f"cannot bind UDP {host}:{port} ({exc})") from None
        self._seq = 0
        self.malformed = 0

    def __enter__(self) -> "UdpHapticClient":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._sock.close()

    def send_pose(self, timestamp: float, position, quaternion=(1.0, 0.0, 0.0, 0.0), buttons: int = 0,
                  grip: float = 0.0) -> int:
        """Send one pose; returns its sequence number."""
        seq = self._seq
        self._sock.sendto(encode_pose(seq, timestamp, position, quaternion, buttons, grip), self.server)
        self._seq += 1
        return seq

    def send_raw(self, data: bytes) -> None:
        """Send arbitrary bytes (tests of malformed packets)."""
        self._sock.sendto(bytes(data), self.server)

    def receive_forces(self, timeout: float = 0.0, max_packets: int = 1024) -> list[ForcePacket]:
        """All force packets queued now (waiting up to ``timeout`` s for the first)."""
        out: list[ForcePacket] = []
        if timeout > 0:
            self._sock.settimeout(timeout)  # wait for the first packet only
        else:
            self._sock.setblocking(False)
        try:
            for _ in range(max_packets):
                try:
                    data, _ = self._sock.recvfrom(2048)
                except (BlockingIOError, socket.timeout, InterruptedError):
                    break
                except OSError:
                    continue
                finally:
                    self._sock.setblocking(False)
                try:
                    out.append(decode_force(data))
                except MalformedPacketError:
                    self.malformed += 1
        finally:
            self._sock.setblocking(False)
        return out
