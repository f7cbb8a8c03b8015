"""The servo in its own process (haptics/servo_process.py) and the real-time helpers.

Behaviour only (forces, records, errors); the servo's timing is measured by
``surgsim bench haptics-flood --servo process`` (docs/benchmarks.md), never asserted here."""

import functools
import threading
import time

import numpy as np
import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.haptics import ServoConfig, SpringWallPhysics, UdpHapticClient
from surgsim_envs.haptics.realtime import periodic_ticks, raise_thread_priority, wait_until
from surgsim_envs.haptics.servo_process import ProcessServoLoop, SeqLockRecord, ServoProcessError
from surgsim_envs.haptics.udp_bridge import UdpDevice


def test_seqlock_record_round_trip_and_sequence():
    rec = SeqLockRecord(3)
    assert rec.read() == (0, [0.0, 0.0, 0.0])  # never written
    rec.write([1.0, -2.5, 3e-9])
    rec.write([4.0, 5.0, 6.0])
    seq, vals = rec.read()
    assert seq == 4 and vals == [4.0, 5.0, 6.0]  # two writes, each +2: even = consistent


def test_seqlock_reader_gives_up_on_a_writer_that_died_mid_write():
    rec = SeqLockRecord(2)
    rec.write([1.0, 2.0])
    rec.buf[0] += 1.0  # a writer killed between its two counter increments
    assert rec.read(tries=50) == (None, None)


def test_seqlock_reader_never_sees_a_torn_record():
    rec = SeqLockRecord(8)
    stop = threading.Event()

    def writer():
        k = 0.0
        while not stop.is_set():
            k += 1.0
            rec.write([k] * 8)

    th = threading.Thread(target=writer)
    th.start()
    try:
        for _ in range(20000):
            _, vals = rec.read()
            assert len(set(vals)) == 1  # all eight from one write
    finally:
        stop.set()
        th.join()


def test_spin_s_is_checked_against_the_period():
    with pytest.raises(ConfigError, match="spin_s"):
        ServoConfig(spin_s=-1e-4)
    with pytest.raises(ConfigError, match=r"period=0\.001"):
        ServoConfig(spin_s=1e-3)


def test_priority_helpers():
    assert raise_thread_priority(False) == "default"
    got = []
    th = threading.Thread(target=lambda: got.append(raise_thread_priority(True)))  # a throwaway thread
    th.start()
    th.join()
    assert got[0] in ("SCHED_FIFO", "nice -10", "default")
    deadline = time.perf_counter() + 2e-3
    assert wait_until(deadline, 5e-4) >= deadline


def test_periodic_ticks_keep_the_rate_and_skip_missed_ticks():
    h = 2e-3
    start = time.perf_counter()
    n = [0]

    def stop():
        n[0] += 1
        return n[0] > 5

    times = list(periodic_ticks(start, h, 5e-4, stop))
    assert len(times) == 5
    assert all(t >= start + i * h for i, t in enumerate(times))        # never early
    # started 50 periods in the past: no burst of 50 catch-up ticks, the next tick waits its turn
    late = time.perf_counter() - 50 * h
    n[0] = 0
    times = list(periodic_ticks(late, h, 5e-4, stop))
    assert len(times) == 5 and times[-1] - times[0] >= 3 * h * 0.99


def test_process_servo_renders_the_spring_wall_force_over_udp():
    # proxy 2 mm into a wall (k_wall 500 N/m behind a 2000 N/m coupling): at rest the hand feels
    # the series stiffness 400 N/m x 2 mm = 0.8 N upward
    phys = SpringWallPhysics(start_position=(0.0, 0.0, 0.005))
    loop = ProcessServoLoop(functools.partial(UdpDevice, port=0), phys, ServoConfig(max_force_rate=1e4))
    loop.start()
    forces = []
    try:
        assert loop.device_address is not None
        with UdpHapticClient(tuple(loop.device_address)) as client:
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < 1.5:
                client.send_pose(time.perf_counter() - t0, (0.0, 0.0, -0.002))
                forces += client.receive_forces(timeout=0.005)
    finally:
        stats = loop.stop()
    np.testing.assert_allclose(phys.proxy, (0.0, 0.0, -0.002))  # the physics got the servo's target
    assert phys.steps > 100 and stats.physics_updates == phys.steps
    # poses got through (how many depends on how often this busy test process is scheduled)
    assert stats.ticks > 100 and loop.device_stats["accepted"] > 0 and loop.device_stats["malformed"] == 0
    assert forces, "no force packet came back"
    assert forces[-1].force[2] == pytest.approx(0.8, rel=0.03)
    assert abs(forces[-1].force[0]) < 1e-9 and abs(forces[-1].force[1]) < 1e-9
    log = loop.force_log  # the child's log of what it rendered, shipped back at stop
    assert len(log) == stats.ticks + 1 and np.all(log.forces[-1] == 0.0)  # + the zero force at stop
    assert log.forces[-2][2] == pytest.approx(0.8, rel=0.03)


def test_run_realtime_calls_on_frame_and_stops_when_it_returns_false():
    calls = []

    def frame(loop):
        calls.append(loop.running)
        return len(calls) < 3

    loop = ProcessServoLoop(functools.partial(UdpDevice, port=0), SpringWallPhysics())
    stats = loop.run_realtime(30.0, on_frame=frame, frame_period=0.01)
    assert calls == [True, True, True] and not loop.running
    assert stats.duration_s < 20.0 and stats.physics_updates == 0  # no pose came: the physics never stepped


def test_force_log_at_capacity_keeps_the_newest_rows_in_order():
    from surgsim_envs.haptics.recording import ForceLog

    log = ForceLog(max_rows=5)
    for i in range(12):
        log.append(i * 1e-3, (i, 0.0, -i), saturated=i % 2 == 0)
    assert len(log) == 5
    np.testing.assert_allclose(log.times, [0.007, 0.008, 0.009, 0.010, 0.011])
    np.testing.assert_allclose(log.forces[:, 0], [7, 8, 9, 10, 11])
    np.testing.assert_array_equal(log.saturated, [False, True, False, True, False])


def _broken_device():
    raise ConfigError("no such device: test")


def test_a_failing_device_factory_is_reported_with_its_message():
    loop = ProcessServoLoop(_broken_device, SpringWallPhysics())
    with pytest.raises(ServoProcessError, match="no such device: test"):
        loop.start()
    assert not loop.running


def test_teleop_servo_process_needs_a_udp_device():
    import argparse

    from surgsim_envs.haptics import teleop

    parser = argparse.ArgumentParser()
    teleop.add_arguments(parser)
    args = parser.parse_args(["palpation", "--device", "scripted", "--servo", "process", "--headless"])
    with pytest.raises(ConfigError, match="--servo process needs a network device"):
        teleop.run(args)


def test_a_script_without_a_main_guard_gets_a_clear_error(tmp_path):
    import os
    import subprocess
    import sys

    script = tmp_path / "no_guard.py"
    script.write_text("import functools\n"
                      "from surgsim_envs.haptics import SpringWallPhysics\n"
                      "from surgsim_envs.haptics.servo_process import ProcessServoLoop\n"
                      "from surgsim_envs.haptics.udp_bridge import UdpDevice\n"
                      "ProcessServoLoop(functools.partial(UdpDevice, port=0), SpringWallPhysics()).run_realtime(1.0)\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    res = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120, env=env)
    assert res.returncode != 0
    assert "ServoProcessError" in res.stderr and "if __name__ == '__main__':" in res.stderr


def test_the_servo_process_stops_when_its_parent_is_killed(tmp_path):
    import os
    import signal
    import subprocess
    import sys

    script = tmp_path / "parent.py"
    script.write_text("import functools, sys, time\n"
                      "from surgsim_envs.haptics import SpringWallPhysics\n"
                      "from surgsim_envs.haptics.servo_process import ProcessServoLoop\n"
                      "from surgsim_envs.haptics.udp_bridge import UdpDevice\n"
                      "if __name__ == '__main__':\n"
                      "    loop = ProcessServoLoop(functools.partial(UdpDevice, port=0), SpringWallPhysics())\n"
                      "    loop.start()\n"
                      "    print(loop._proc.pid, flush=True)\n"
                      "    time.sleep(60)\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    parent = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True, env=env)
    try:
        child = int(parent.stdout.readline())
        os.kill(parent.pid, signal.SIGKILL)  # no cleanup runs in the parent
        parent.wait(timeout=10)
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            try:
                os.kill(child, 0)
            except ProcessLookupError:
                break
            with open(f"/proc/{child}/stat") as fh:
                if fh.read().split()[2] == "Z":  # exited, waiting to be reaped by init
                    break
            time.sleep(0.05)
        else:
            os.kill(child, signal.SIGKILL)
            pytest.fail("the servo process outlived its killed parent by 10 s")
    finally:
        if parent.poll() is None:
            parent.kill()


def test_process_servo_rejects_bad_arguments():
    with pytest.raises(ConfigError, match="device_factory"):
        ProcessServoLoop("udp:5555", SpringWallPhysics())
    with pytest.raises(ConfigError, match="not a haptic physics"):
        ProcessServoLoop(functools.partial(UdpDevice, port=0), object())
    with pytest.raises(ConfigError, match="not running"):
        ProcessServoLoop(functools.partial(UdpDevice, port=0), SpringWallPhysics()).stop()
