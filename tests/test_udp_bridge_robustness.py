"""UDP bridge under hostile input: overflowing quaternions, the session gate on a live socket,
bounded reads under a garbage flood, zero force before the first pose."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from surgsim_envs.haptics import DeviceLimits, DeviceMapping, ServoConfig, ServoLoop, SpringWallPhysics
from surgsim_envs.haptics.device import DeviceState, HapticDevice
from surgsim_envs.haptics.quaternion import unit_quaternion
from surgsim_envs.haptics.pose_protocol import decode_pose, encode_pose
from surgsim_envs.haptics.session_gate import OPEN_PACKETS, SESSION_TIMEOUT_S
from surgsim_envs.haptics.udp_bridge import UdpDevice, UdpHapticClient
from udp_support import poll_until  # noqa: E402



@pytest.mark.parametrize("quat, expected", [
    ((1e300, 0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)),
    ((1e300, 1e300, 0.0, 0.0), (math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0)),
    ((0.0, 0.0, -1.7e308, 1.7e308), (0.0, 0.0, -math.sqrt(0.5), math.sqrt(0.5))),
    ((3e-6, 0.0, 4e-6, 0.0), (0.6, 0.0, 0.8, 0.0)),
])
def test_decoded_quaternion_is_unit_even_when_squares_overflow(quat, expected):
    p = decode_pose(encode_pose(1, 0.0, (0, 0, 0), quat))
    np.testing.assert_allclose(p.quaternion, expected, rtol=1e-15)
    assert unit_quaternion((0.0, 0.0, 0.0, 0.0)) is None
    assert unit_quaternion((1e-7, 0, 0, 0)) is None


class _HugeQuatDevice(HapticDevice):
    """A device whose reading holds a quaternion that overflows when squared."""

    def _read(self, t):
        return DeviceState(time=t, position=np.zeros(3), quaternion=np.array([1e300, 0.0, 1e300, 0.0]))


def test_servo_normalises_an_overflowing_quaternion_instead_of_zeroing_it():
    phys = SpringWallPhysics(start_position=(0, 0, 0.01))
    with _HugeQuatDevice() as dev:
        loop = ServoLoop(dev, phys)
        for i in range(5):
            loop.tick(i * 1e-3, physics_until=phys.time + 1e-3)
    np.testing.assert_allclose(phys.proxy_quat, (math.sqrt(0.5), 0.0, math.sqrt(0.5), 0.0), rtol=1e-12)
    assert loop.stats.rejected_poses == 0


def test_bridge_survives_a_far_ahead_packet_and_a_client_restart():
    dev = UdpDevice(port=0)
    with dev, UdpHapticClient(dev.address) as client:
        for i in range(5):
            client.send_pose(i * 1e-3, (0.0, 0.0, 0.001 * i))
        assert poll_until(dev, lambda: dev.stats.accepted == 5 - OPEN_PACKETS + 1)
        client.send_raw(encode_pose(0xFFFF0000, 0.0, (0.05, 0.05, 0.05), session=client.session))  # stray
        for i in range(5, 10):
            client.send_pose(i * 1e-3, (0.0, 0.0, 0.001 * i))
        assert poll_until(dev, lambda: dev.stats.accepted == 10 - OPEN_PACKETS + 1)
        assert dev.stats.stale == OPEN_PACKETS - 1 + 1
        assert dev.read(0.0).position[2] == pytest.approx(0.009)
    # a new client process (new port, new session id, sequence from 0) takes over once the old
    # session has been silent for SESSION_TIMEOUT_S, after OPEN_PACKETS counting poses
    time.sleep(SESSION_TIMEOUT_S + 0.05)
    with dev, UdpHapticClient(dev.address) as restarted:
        for i in range(6):
            restarted.send_pose(i * 1e-3, (0.0, 0.01 * i, 0.0))
        assert poll_until(dev, lambda: dev.stats.accepted == (10 - OPEN_PACKETS + 1) + (6 - OPEN_PACKETS + 1))
        assert dev.stats.takeovers == 1
        assert dev.read(0.0).position[1] == pytest.approx(0.05)


def test_garbage_flood_is_read_in_bounded_batches_and_the_pose_gets_through():
    dev = UdpDevice(port=0, max_drain=16)
    with dev, UdpHapticClient(dev.address) as client:
        for k in range(200):  # fewer than the kernel's default receive buffer holds
            client.send_raw(bytes([k % 256]) * (1 + k % 200))
        for _ in range(OPEN_PACKETS):
            client.send_pose(0.0, (0.01, 0.0, 0.0))
        polls = 0
        while dev.stats.accepted == 0 and polls < 300:
            before = dev.stats.received
            dev.poll()
            assert dev.stats.received - before <= 16  # one servo tick never reads more
            polls += 1
            if dev.stats.received == before:
                time.sleep(0.001)
        assert dev.stats.accepted == 1 and dev.stats.malformed == 200
        assert dev.stats.stale == OPEN_PACKETS - 1
        assert polls >= 200 // 16
        assert dev.read(0.0).position[0] == pytest.approx(0.01)


def test_no_force_reaches_the_device_before_its_first_pose():
    # the workspace centre maps 2.5 cm into a stiff wall: rendering it would saturate the device
    phys = SpringWallPhysics(start_position=(0, 0, 0.0))
    dev = UdpDevice(port=0, limits=DeviceLimits(max_force=3.3))
    config = ServoConfig(mapping=DeviceMapping(origin=(0.0, 0.0, -0.05)))
    with dev, UdpHapticClient(dev.address) as client:
        loop = ServoLoop(dev, phys, config)
        assert not dev.has_pose
        for i in range(50):
            loop.tick(i * 1e-3, physics_until=phys.time + 1e-3)
        assert np.all(dev.force_log.forces == 0.0) and loop.proxy_target is None
        assert phys.steps == 0 and loop.stats.saturated == 0
        for k in range(OPEN_PACKETS):  # the hand, out of contact; the stream opens on the last
            assert not dev.has_pose
            client.send_pose(0.05, (0.0, 0.0, 0.05))
        assert poll_until(dev, lambda: dev.has_pose)
        loop.tick(0.05, physics_until=phys.time + 1e-3)
        assert loop.proxy_target[2] == pytest.approx(0.0)


def test_one_overflowing_packet_does_not_end_a_teleoperation_of_the_scene():
    scene_adapter = pytest.importorskip("surgsim_envs.haptics.scene_adapter", exc_type=ImportError)
    phys = scene_adapter.make_haptic_simulation("palpation")
    dev = UdpDevice(port=0)
    config = ServoConfig(mapping=DeviceMapping(origin=tuple(phys.home_position)))
    with dev, UdpHapticClient(dev.address) as client:
        loop = ServoLoop(dev, phys, config)
        for _ in range(OPEN_PACKETS):
            client.send_pose(0.0, (0.0, 0.0, 0.0))
        assert poll_until(dev, lambda: dev.has_pose)
        client.send_raw(encode_pose(OPEN_PACKETS, 0.001, (0.0, 0.0, 0.0), (1e300, 0.0, 0.0, 1e300),
                                    session=client.session))
        for i in range(20):
            loop.tick(i * 1e-3, physics_until=phys.time + 1e-3)
        assert dev.stats.accepted == 2 and dev.stats.malformed == 0
        np.testing.assert_allclose(loop._target_quat, (math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)), rtol=1e-12)
        assert np.all(np.isfinite(dev.force_log.forces))
