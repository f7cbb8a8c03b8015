"""A network bridge for remote haptic devices: pose packets in, force packets out, over UDP.

The wire format (session ids, sequence numbers, optional HMAC-SHA256 tags) is in
:mod:`~surgsim_envs.haptics.pose_protocol`; which packets move the tool is decided by
:class:`~surgsim_envs.haptics.session_gate.SessionGate`. This module holds the sockets.

By default the simulator binds ``127.0.0.1`` (loopback only). Binding any other interface needs
a key: pass ``key=`` (bytes or hex, at least 16 bytes) or let :class:`UdpDevice` draw one
(:attr:`UdpDevice.key`); the device side passes the same key to :class:`UdpHapticClient`. Every
packet then carries an HMAC-SHA256 tag and untagged or forged packets are dropped.

A datagram is *malformed* (counted in ``stats.malformed`` and dropped; the bridge never raises
for it) when its length, magic, version, type or tag is wrong, a number is non-finite, the
quaternion has zero length (after scaling by its largest component, so ``1e300`` components that
overflow when squared are still normalised correctly) or grip is outside [0, 1]. A valid pose
that the session gate does not apply is counted in ``stats.stale``. Forces go back to the
address of the last applied pose, carrying its session id.

Flooding
--------
One :meth:`UdpDevice.poll` (once per servo tick) reads at most ``max_drain`` datagrams
(default 32) and stops after ``max_poll_s`` (default 0.2 ms) of wall clock, so a flood of
garbage cannot starve the 1 kHz servo; the rest stays queued in the kernel (which drops what
overflows its buffer). Datagrams of the wrong length are rejected before any decoding.

Until a stream has opened (three counting packets) the device reports *no pose*
(:attr:`UdpDevice.has_pose` is False) and the servo renders zero force.
"""

from __future__ import annotations

import ipaddress
import math
import socket
import time
from dataclasses import dataclass

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError
from surgsim_envs.haptics.device import DeviceLimits, DeviceState, HapticDevice
from surgsim_envs.haptics.pose_protocol import (POSE_SIZE, TAG_SIZE, ForcePacket, MalformedPacketError,
                                                PosePacket, check_key, decode_force, decode_pose,
                                                encode_force, encode_pose, new_session_id, new_session_key)
from surgsim_envs.haptics.session_gate import SessionGate

DEFAULT_HOST = "127.0.0.1"


def is_loopback(host: str) -> bool:
    """Whether ``host`` names the loopback interface only."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@dataclass
class BridgeStats:
    received: int = 0
    accepted: int = 0
    malformed: int = 0
    stale: int = 0
    takeovers: int = 0
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
    ``max_poll_s`` s per call) and returns the newest applied pose (the handle stays where it was
    if nothing new arrived). Before the first pose it reports the workspace centre with
    :attr:`has_pose` False; the servo renders zero force until a pose arrives. ``port=0`` binds
    a free port: see :attr:`address` after ``connect()``.

    ``key``: the per-session secret (bytes or hex, >= 16 bytes) that authenticates every packet.
    Required for any bind other than loopback; when it is not given there, a fresh one is drawn
    (:attr:`key`: hand it to the device side). To run the device in a servo process, draw the
    key in the parent (``new_session_key()``) and pass it in the device factory.
    """

    name = "udp"

    def __init__(self, port: int = 0, host: str = DEFAULT_HOST, limits: DeviceLimits | None = None,
                 max_drain: int = 32, max_poll_s: float = 2e-4, key: bytes | str | None = None):
        super().__init__(limits)
        _check_endpoint(host, port)
        key = check_key(key)
        if key is None and not is_loopback(host):
            key = new_session_key()
        self.key: bytes | None = key
        validate.integer(max_drain, "max_drain", lo=1, fix="the most datagrams one poll reads, e.g. 64")
        validate.positive(max_poll_s, "max_poll_s", unit="s", fix="a time budget per poll, e.g. 2e-4")
        self.host, self.port = host, port
        self.max_drain = int(max_drain)
        self.max_poll_s = float(max_poll_s)
        self.stats = BridgeStats()
        self._sock: socket.socket | None = None
        self._peer = None
        self._gate = SessionGate(authenticated=key is not None)
        self._session_out = 0
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
    def _pose_bytes(self) -> int:
        return POSE_SIZE + (TAG_SIZE if self.key is not None else 0)

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
            if len(data) != self._pose_bytes:
                self.stats.malformed += 1
                continue
            try:
                pkt = decode_pose(data, self.key)
            except MalformedPacketError:
                self.stats.malformed += 1
                continue
            takeovers = self._gate.takeovers
            if not self._gate.admit(pkt.session, pkt.seq, addr, time.monotonic()):
                self.stats.stale += 1
                continue
            self.stats.takeovers += self._gate.takeovers - takeovers
            self._peer, self._session_out = addr, pkt.session
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
            packet = encode_force(self._seq_out, t if math.isfinite(t) else 0.0, force, self.last_saturated,
                                  session=self._session_out, key=self.key)
            self._sock.sendto(packet, self._peer)
            self._seq_out += 1
            self.stats.forces_sent += 1
        except OSError:
            self.stats.send_errors += 1


class UdpHapticClient:
    """Device side (a remote hand, or a test): sends pose packets, receives force packets.

    Each client is one session: it draws a random session id (``session``) and numbers its
    poses from 0. ``key`` is the simulator's per-session secret when it requires one (any bind
    other than loopback): poses are then tagged, and force packets that do not verify or that
    answer another session are dropped (counted in :attr:`malformed`). Use as a context manager;
    sockets are always closed on exit."""

    def __init__(self, server: tuple[str, int], host: str = DEFAULT_HOST, port: int = 0,
                 key: bytes | str | None = None, session: int | None = None):
        _check_endpoint(host, port)
        self.key = check_key(key)
        self.session = new_session_id() if session is None else int(session) & 0xFFFFFFFFFFFFFFFF
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
        self._sock.sendto(encode_pose(seq, timestamp, position, quaternion, buttons, grip, session=self.session,
                                      key=self.key), self.server)
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
                    packet = decode_force(data, self.key)
                except MalformedPacketError:
                    self.malformed += 1
                    continue
                if packet.session != self.session:
                    self.malformed += 1
                    continue
                out.append(packet)
        finally:
            self._sock.setblocking(False)
        return out
