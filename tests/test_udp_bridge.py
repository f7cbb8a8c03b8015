"""UDP bridge: packet format, loopback round trip (127.0.0.1 only), malformed packets."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.haptics import DeviceLimits, ServoLoop, SpringWallPhysics
from surgsim_envs.haptics.pose_protocol import (FORCE_SIZE, POSE_SIZE, MalformedPacketError, decode_force, decode_pose,
                                                encode_force, encode_pose)
from surgsim_envs.haptics.session_gate import OPEN_PACKETS
from surgsim_envs.haptics.udp_bridge import UdpDevice, UdpHapticClient
from udp_support import poll_until  # noqa: E402


def test_packet_round_trip_and_documented_sizes():
    assert (POSE_SIZE, FORCE_SIZE) == (90, 51)
    raw = encode_pose(7, 1.25, (0.01, -0.02, 0.03), (0.0, 1.0, 0.0, 0.0), buttons=5, grip=0.5, session=2**64 - 3)
    assert len(raw) == POSE_SIZE and raw[:4] == b"SSHP" and raw[4] == 2
    assert struct.unpack_from("<Q", raw, 6)[0] == 2**64 - 3 and struct.unpack_from("<I", raw, 14)[0] == 7
    p = decode_pose(raw)
    assert (p.session, p.seq, p.timestamp, p.position, p.quaternion, p.buttons, p.grip) == (
        2**64 - 3, 7, 1.25, (0.01, -0.02, 0.03), (0.0, 1.0, 0.0, 0.0), 5, 0.5)
    f = decode_force(encode_force(3, 0.5, (1.0, -2.0, 0.25), saturated=True, session=11))
    assert (f.session, f.seq, f.timestamp, f.force, f.saturated) == (11, 3, 0.5, (1.0, -2.0, 0.25), True)


def _malformed():
    good = encode_pose(1, 0.0, (0, 0, 0))
    yield b""
    yield good[:-1]
    yield good + b"\x00"
    yield b"XXXX" + good[4:]
    yield good[:4] + bytes([1]) + good[5:]  # version 1 (no session id)
    yield good[:5] + bytes([2]) + good[6:]  # a force type on the pose port
    yield encode_pose(1, 0.0, (math.nan, 0, 0))
    yield encode_pose(1, math.inf, (0, 0, 0))
    yield encode_pose(1, 0.0, (0, 0, 0), (0, 0, 0, 0))
    yield encode_pose(1, 0.0, (0, 0, 0), grip=1.5)
    yield b'{"version": 1, "position": [0, 0, 0]}'


@pytest.mark.parametrize("data", list(_malformed()))
def test_malformed_pose_packets_raise(data):
    with pytest.raises(MalformedPacketError):
        decode_pose(data)



def test_loopback_round_trip_poses_in_forces_out_malformed_rejected():
    dev = UdpDevice(port=0, limits=DeviceLimits(max_force=5.0))
    client = None
    try:
        dev.connect()
        host, port = dev.address
        assert host == "127.0.0.1"
        client = UdpHapticClient((host, port))
        phys = SpringWallPhysics(start_position=(0, 0, 0.0))
        loop = ServoLoop(dev, phys)
        depths = np.linspace(0.0, 0.004, 40)
        for _ in range(OPEN_PACKETS - 1):  # the stream opens on its third counting pose
            client.send_pose(0.0, (0.0, 0.0, 0.0), grip=0.25)
        for i, d in enumerate(depths):
            client.send_pose(i * 1e-3, (0.0, 0.0, -d), grip=0.25)
            if i % 10 == 3:  # interleave garbage: counted, never fatal
                client.send_raw(b"\x00" * 7)
                client.send_raw(encode_pose(999, 0, (math.nan, 0, 0)))
            assert poll_until(dev, lambda: dev.stats.accepted == i + 1)
            loop.tick(i * 1e-3, physics_until=phys.time + 1e-3)
        # 40 poses accepted, 8 malformed rejected, the loop kept running
        assert dev.stats.accepted == len(depths)
        assert dev.stats.malformed == 8
        assert loop.stats.rejected_poses == 0
        assert phys.proxy[2] == pytest.approx(-depths[-1])
        assert phys.grip == pytest.approx(0.25)

        forces = []
        for _ in range(200):
            forces += client.receive_forces(timeout=0.01)
            if len(forces) >= len(depths):
                break
        assert len(forces) == len(depths)
        assert [f.seq for f in forces] == list(range(len(depths)))
        fz = np.array([f.force[2] for f in forces])
        np.testing.assert_allclose(fz, dev.force_log.forces[:, 2])  # what was sent is what arrived
        assert fz[-1] > 0.5 and np.all(np.abs(fz) <= 5.0)  # pushing into the wall is felt, limited

        # an older sequence number is stale, not applied
        stale = encode_pose(0, 0.0, (0.0, 0.0, 0.05), session=client.session)
        client.send_raw(stale)
        assert poll_until(dev, lambda: dev.stats.stale == OPEN_PACKETS - 1 + 1)
        assert dev.read(1.0).position[2] == pytest.approx(-depths[-1])
    finally:
        if client is not None:
            client.close()
        dev.close()
    assert dev._sock is None and client._sock.fileno() == -1


def test_bridge_validates_endpoint_and_requires_connect():
    with pytest.raises(ConfigError, match="port"):
        UdpDevice(port=70000)
    dev = UdpDevice(port=0)
    with pytest.raises(ConfigError, match="connect"):
        dev.address
    with dev:
        port = dev.address[1]
        with pytest.raises(ConfigError, match="cannot bind"):
            UdpDevice(port=port).connect()
    assert not dev.connected


def test_force_packet_flags_saturation():
    dev = UdpDevice(port=0, limits=DeviceLimits(max_force=1.0))
    with dev, UdpHapticClient(dev.address) as client:
        for _ in range(OPEN_PACKETS):
            client.send_pose(0.0, (0, 0, 0))
        assert poll_until(dev, lambda: dev.stats.accepted == 1)
        dev.send_force((0.0, 0.0, 3.0), 0.0)
        got = []
        for _ in range(100):
            got += client.receive_forces(timeout=0.01)
            if got:
                break
        assert got and got[0].saturated and got[0].force[2] == pytest.approx(1.0)
    assert struct.calcsize("<4sBBQIddddB") == FORCE_SIZE
