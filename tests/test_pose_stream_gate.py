"""The haptic pose stream keeps to the sender that opened it: spoofed, stray and replayed packets
neither move the tool nor lock the genuine stream out; authenticated packets (HMAC-SHA256) on any
bind other than loopback."""

from __future__ import annotations


import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.haptics.pose_protocol import (
    POSE_SIZE,
    TAG_SIZE,
    MalformedPacketError,
    check_key,
    decode_force,
    decode_pose,
    encode_force,
    encode_pose,
    new_session_key,
)
from surgsim_envs.haptics.session_gate import OPEN_PACKETS, SEQ_WINDOW, SESSION_TIMEOUT_S, SessionGate
from surgsim_envs.haptics.udp_bridge import UdpDevice, UdpHapticClient, is_loopback
from udp_support import poll_until  # noqa: E402

DEV, ATTACKER = ("127.0.0.1", 5000), ("127.0.0.1", 6000)
GENUINE, SPOOF = 0x1111, 0x2222


def _opened(gate, session=GENUINE, addr=DEV, t0=0.0):
    """Open ``session`` with OPEN_PACKETS counting packets at 1 kHz; returns the next seq."""
    admitted = [gate.admit(session, s, addr, t0 + 1e-3 * s) for s in range(OPEN_PACKETS)]
    assert admitted == [False] * (OPEN_PACKETS - 1) + [True]
    return OPEN_PACKETS


def test_a_single_stray_never_opens_a_stream_and_strays_do_not_delay_the_genuine_one():
    g = SessionGate()
    for k in range(50):  # strays: each a different session or a non-counting number
        assert not g.admit(1000 + k, 7 * k, ATTACKER, 1e-4 * k)
        assert not g.admit(SPOOF, (k * 40_000_000) & 0xFFFFFFFF, ATTACKER, 1e-4 * k + 5e-5)
    assert g.session is None
    # the genuine stream interleaved with strays opens on its own third packet
    got = []
    for s in range(5):
        got.append(g.admit(GENUINE, s, DEV, 0.01 + 1e-3 * s))
        assert not g.admit(SPOOF, 10**6 + 2 * s, ATTACKER, 0.01 + 1e-3 * s + 1e-4)
    assert got == [False] * (OPEN_PACKETS - 1) + [True] * (5 - OPEN_PACKETS + 1)
    assert (g.session, g.addr) == (GENUINE, DEV)


def test_spoofed_counting_packets_do_not_take_over_a_live_session():
    g = SessionGate()
    seq = _opened(g)
    t = 0.01
    for k in range(2000):  # an attacker counting at 1 kHz interleaved with the genuine stream
        assert not g.admit(SPOOF, k, ATTACKER, t)
        assert not g.admit(GENUINE, 500_000 + k, ATTACKER, t)  # the genuine id from another address
        assert g.admit(GENUINE, seq, DEV, t + 1e-4)
        seq, t = seq + 1, t + 1e-3
    assert (g.session, g.addr, g.takeovers) == (GENUINE, DEV, 0)


def test_no_lockout_after_any_number_of_strays_and_the_window_bound():
    g = SessionGate()
    seq = _opened(g)
    for k in range(300):
        assert not g.admit(GENUINE, (seq + SEQ_WINDOW + 1 + k) & 0xFFFFFFFF, DEV, 0.01)  # far ahead
        assert not g.admit(GENUINE, seq - 1 - (k % OPEN_PACKETS), DEV, 0.01)             # old
    assert g.admit(GENUINE, seq, DEV, 0.011)
    assert not g.admit(GENUINE, seq + SEQ_WINDOW + 1, DEV, 0.012)
    assert g.admit(GENUINE, seq + SEQ_WINDOW, DEV, 0.012)


def test_replays_are_refused_after_any_idle_time():
    g = SessionGate()
    seq = _opened(g)
    t_idle = 0.01 + 10 * SESSION_TIMEOUT_S
    for s in range(seq):  # the session's own old packets, from its address or another
        assert not g.admit(GENUINE, s, DEV, t_idle)
        assert not g.admit(GENUINE, s, ATTACKER, t_idle + 1e-3)
    # after silence the genuine device resumes its own numbering
    assert g.admit(GENUINE, seq, DEV, t_idle + 2e-3)


def test_a_restarted_device_takes_over_a_silent_session_and_the_old_one_is_retired():
    g = SessionGate()
    _opened(g)
    new = 0x3333
    # while the session is alive a restarted client is not adopted, however long it counts
    assert not any(g.admit(new, s, ATTACKER, 0.004 + 1e-3 * s) for s in range(10))
    # once the old session is silent, its next counting packet takes over
    t = 0.004 + SESSION_TIMEOUT_S + 0.01
    assert g.admit(new, 10, ATTACKER, t)
    assert (g.session, g.addr, g.takeovers, g.opened) == (new, ATTACKER, 1, 2)
    # the old session cannot come back, not even counting and after silence
    t += 2 * SESSION_TIMEOUT_S
    assert not any(g.admit(GENUINE, 100 + s, DEV, t + 1e-3 * s) for s in range(10))
    assert g.session == new


def test_authenticated_gate_lets_the_session_change_address():
    g = SessionGate(authenticated=True)
    seq = _opened(g)
    assert g.admit(GENUINE, seq, ("127.0.0.1", 7777), 0.01)  # NAT rebinding: the tag vouches for it


def test_packets_tagged_with_a_key_verify_and_forgeries_do_not():
    key = new_session_key()
    raw = encode_pose(5, 0.25, (0.01, 0.0, -0.02), session=42, key=key)
    assert len(raw) == POSE_SIZE + TAG_SIZE
    p = decode_pose(raw, key)
    assert (p.session, p.seq, p.position) == (42, 5, (0.01, 0.0, -0.02))
    with pytest.raises(MalformedPacketError, match="does not verify"):
        decode_pose(raw, new_session_key())
    flipped = bytearray(raw)
    flipped[30] ^= 1  # one bit of the position
    with pytest.raises(MalformedPacketError, match="does not verify"):
        decode_pose(bytes(flipped), key)
    with pytest.raises(MalformedPacketError, match="no authentication tag"):
        decode_pose(encode_pose(5, 0.25, (0, 0, 0), session=42), key)
    with pytest.raises(MalformedPacketError, match="no key is set"):
        decode_pose(raw)
    f = decode_force(encode_force(1, 0.5, (0.0, 0.0, 1.5), session=42, key=key), key)
    assert (f.session, f.force) == (42, (0.0, 0.0, 1.5))


@pytest.mark.parametrize("bad, match", [(b"short", "at least 16"), ("zz" * 16, "not hex"), (1234, "at least 16")])
def test_bad_keys_are_refused_with_the_fix(bad, match):
    with pytest.raises(ConfigError, match=match):
        check_key(bad)
    assert check_key(new_session_key().hex()) is not None



def test_a_bind_beyond_loopback_requires_tagged_packets():
    assert is_loopback("127.0.0.1") and is_loopback("localhost") and not is_loopback("0.0.0.0")
    assert UdpDevice(port=0).key is None
    dev = UdpDevice(port=0, host="0.0.0.0")  # every interface: a key is drawn
    assert dev.key is not None and len(dev.key) == 32
    with dev:
        server = ("127.0.0.1", dev.address[1])
        with UdpHapticClient(server) as plain, UdpHapticClient(server, key=dev.key.hex()) as keyed:
            for i in range(2 * OPEN_PACKETS):
                plain.send_pose(i * 1e-3, (0.0, 0.0, 0.03))
            assert poll_until(dev, lambda: dev.stats.malformed == 2 * OPEN_PACKETS)
            assert not dev.has_pose
            for i in range(OPEN_PACKETS + 2):
                keyed.send_pose(i * 1e-3, (0.0, 0.0, -0.001 * i))
            assert poll_until(dev, lambda: dev.stats.accepted == 3)
            assert dev.read(0.0).position[2] == pytest.approx(-0.001 * (OPEN_PACKETS + 1))
            dev.send_force((0.0, 0.0, 0.5), 0.0)
            got = []
            for _ in range(100):
                got += keyed.receive_forces(timeout=0.01)
                if got:
                    break
            assert got and got[0].session == keyed.session and got[0].force[2] == pytest.approx(0.5)
            assert keyed.malformed == 0 and plain.receive_forces(timeout=0.01) == []
