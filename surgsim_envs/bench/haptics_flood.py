"""``surgsim bench haptics-flood``: the 1 kHz servo period while its UDP port is flooded.

A device client process sends genuine pose packets at ``--pose-hz`` (1 kHz) to a
:class:`~surgsim_envs.haptics.udp_bridge.UdpDevice` on loopback; the threaded servo loop runs
against the analytic spring wall with ``--fake-work`` s of busy work per physics step (or the
palpation scene with ``--scene``) for ``--duration`` s. The same run is made twice in this
process: once quiet, once while ``--flooders`` other processes send garbage datagrams (random
lengths and bytes, a quarter of them valid-length packets with a bad magic) as fast as they can
(or at ``--flood-rate`` datagrams/s each).

First, the cost of one ``poll()`` with 200 garbage datagrams queued is measured in this
process without threads, for this build's bound and for the old unbounded read (256 datagrams,
no time budget): the servo's own cost per tick under a flood, little affected by CPU contention.
Reported per run: servo period median / p99 / max (ms), overruns, genuine poses accepted, the
bridge's received / malformed / truncated-poll counts, and the flood rate actually achieved
(datagrams/s sent, the *load*). Every figure depends on the machine and its load (reported);
no test asserts them. The bound that keeps the servo alive is ``UdpDevice.max_drain`` datagrams
and ``max_poll_s`` s per poll (see udp_bridge).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import time

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError


def _pose_sender(addr, rate_hz: float, stop, sent, ready) -> None:  # runs in a child process
    from surgsim_envs.haptics.udp_bridge import UdpHapticClient

    with UdpHapticClient(tuple(addr)) as client:
        ready.set()
        t0 = time.perf_counter()
        i = 0
        while not stop.is_set():
            deadline = t0 + i / rate_hz
            now = time.perf_counter()
            if deadline > now:
                time.sleep(deadline - now)
            client.send_pose(time.perf_counter() - t0, (0.0, 0.0, -0.002 - 0.001 * np.sin(i * 1e-3)))
            i += 1
            if i % 100 == 0:
                sent.value = i
        sent.value = i


def _flooder(addr, seed: int, stop, sent, ready, rate: float) -> None:  # runs in a child process
    import socket

    from surgsim_envs.haptics.pose_protocol import POSE_SIZE

    rng = np.random.default_rng(seed)
    pool = [rng.bytes(int(n)) for n in rng.integers(1, 1400, 64)]
    pool += [b"XXXX" + rng.bytes(POSE_SIZE - 4) for _ in range(21)]
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    n = 0
    ready.set()
    t0 = time.perf_counter()
    try:
        while not stop.is_set():
            for data in pool:
                try:
                    sock.sendto(data, tuple(addr))
                    n += 1
                except OSError:
                    pass
            sent.value = n
            if rate > 0:  # hold the average rate
                ahead = n / rate - (time.perf_counter() - t0)
                if ahead > 0:
                    time.sleep(ahead)
    finally:
        sock.close()
        sent.value = n


def _physics(scene: bool, fake_work: float):
    if scene:
        from surgsim_envs.bench.haptics_speed import _build_physics

        phys, info, contact_z, home = _build_physics(False, fake_work)
        return phys, info, home
    from surgsim_envs.haptics.fake_physics import SpringWallPhysics

    phys = SpringWallPhysics(start_position=(0.0, 0.0, 0.005), work_seconds=fake_work)
    return phys, {"physics": "fake_spring_wall", "fake_work_s": fake_work}, np.zeros(3)


def _free_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _one_run(duration: float, flooders: int, pose_hz: float, scene: bool, fake_work: float, max_drain: int,
             max_poll_s: float, flood_rate: float = 0.0, spin_s: float = 2e-4, priority: bool = True,
             servo: str = "thread") -> dict:
    import functools

    from surgsim_envs.haptics import DeviceLimits, DeviceMapping, ServoConfig, ServoLoop
    from surgsim_envs.haptics.servo_process import ProcessServoLoop
    from surgsim_envs.haptics.udp_bridge import UdpDevice

    ctx = mp.get_context("spawn")
    phys, info, home = _physics(scene, fake_work)
    make_dev = functools.partial(UdpDevice, port=_free_port(), limits=DeviceLimits(max_force=10.0),
                                 max_drain=max_drain, max_poll_s=max_poll_s)
    config = ServoConfig(mapping=DeviceMapping(origin=tuple(home)), spin_s=spin_s, realtime_priority=priority)
    dev = make_dev()  # the thread servo's device; the process servo builds its own in the child
    stop = ctx.Event()
    procs = []
    addr = ("127.0.0.1", make_dev.keywords["port"])
    with dev if servo == "thread" else _nothing():
        pose_sent = ctx.Value("q", 0)
        flood_sent = [ctx.Value("q", 0) for _ in range(flooders)]
        ready = [ctx.Event() for _ in range(1 + flooders)]
        procs.append(ctx.Process(target=_pose_sender, args=(addr, pose_hz, stop, pose_sent, ready[0]), daemon=True))
        procs += [ctx.Process(target=_flooder, args=(addr, 100 + k, stop, flood_sent[k], ready[1 + k], flood_rate),
                              daemon=True) for k in range(flooders)]
        for p in procs:
            p.start()
        try:
            for ev in ready:  # spawned children import numpy: slow on a loaded machine
                if not ev.wait(timeout=60.0):
                    raise ConfigError("a pose/flood child process did not start within 60 s")
            time.sleep(0.5)  # the flood builds up
            if servo == "thread":
                flood0 = dev.stats.received
                loop = ServoLoop(dev, phys, config)
                t0 = time.perf_counter()
                f0 = sum(v.value for v in flood_sent)
                stats = loop.run_realtime(duration, frame_period=0.05)
            else:
                flood0 = 0
                loop = ProcessServoLoop(make_dev, phys, config)
                loop.start()  # spawning the servo process takes ~1 s; the run is timed from its start
                t0 = time.perf_counter()
                f0 = sum(v.value for v in flood_sent)
                time.sleep(duration)
                stats = loop.stop()
            wall = time.perf_counter() - t0
            f1 = sum(v.value for v in flood_sent)
        finally:
            stop.set()
            for p in procs:
                p.join(timeout=5.0)
                if p.is_alive():
                    p.terminate()
        from surgsim_envs.haptics.udp_bridge import BridgeStats

        bridge = dev.stats if servo == "thread" else BridgeStats(**loop.device_stats)
    return {
        "flooders": flooders, "period_median_ms": stats.period_median_ms, "period_p99_ms": stats.period_p99_ms,
        "period_max_ms": stats.period_max_ms, "overruns": stats.overruns, "ticks": stats.ticks, "wall_s": wall,
        "poses_sent": int(pose_sent.value), "poses_accepted": bridge.accepted, "datagrams_received": bridge.received,
        "received_during_run": bridge.received - flood0, "malformed": bridge.malformed,
        "polls_truncated": bridge.polls_truncated, "flood_datagrams_sent_during_run": int(f1 - f0),
        "flood_rate_per_s": (f1 - f0) / wall if flooders else 0.0, "max_force_n": stats.max_force_n,
        "scheduling": stats.scheduling, "spin_s": spin_s, "servo": servo, **info,
    }


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def poll_cost(max_drain: int, max_poll_s: float, polls: int = 300, queue: int = 200) -> dict:
    """Wall time of one ``UdpDevice.poll()`` with ``queue`` garbage datagrams waiting (refilled
    before every poll, in this process, no threads): median / p99 / max in ms and datagrams read
    per poll. This is the servo's cost per tick under a flood, independent of CPU contention."""
    from surgsim_envs.haptics.udp_bridge import UdpDevice, UdpHapticClient

    rng = np.random.default_rng(0)
    pool = [rng.bytes(int(n)) for n in rng.integers(1, 1400, 64)]
    times, reads = [], []
    dev = UdpDevice(port=0, max_drain=max_drain, max_poll_s=max_poll_s)
    with dev, UdpHapticClient(dev.address) as client:
        for _ in range(polls):
            for k in range(queue):
                client.send_raw(pool[k % len(pool)])
            before = dev.stats.received
            t0 = time.perf_counter()
            dev.poll()
            times.append(time.perf_counter() - t0)
            reads.append(dev.stats.received - before)
            while True:  # drain the rest so every poll starts from the same queue
                n = dev.stats.received
                dev.poll()
                if dev.stats.received == n:
                    break
    t = np.array(times) * 1e3
    return {"max_drain": max_drain, "max_poll_s": max_poll_s, "queue": queue, "polls": polls,
            "poll_median_ms": float(np.median(t)), "poll_p99_ms": float(np.percentile(t, 99)),
            "poll_max_ms": float(t.max()), "reads_per_poll_median": float(np.median(reads))}


#: s, the longest servo run of one figure (two runs per call)
MAX_RUN_S = 600.0


def run_bench(duration: float = 5.0, flooders: int = 1, pose_hz: float = 1000.0, scene: bool = False,
              fake_work: float = 3e-4, max_drain: int = 32, max_poll_s: float = 2e-4, flood_rate: float = 0.0,
              spin_s: float = 2e-4, priority: bool = True, servo: str = "thread") -> dict:
    """A quiet run, then a flooded one; returns both rows and the machine load."""
    if servo not in ("thread", "process"):
        raise ConfigError(f"--servo must be 'thread' or 'process', got {servo!r}")
    validate.duration(duration, "--duration", hi=MAX_RUN_S, fix=f"seconds of servo per run in (0, {MAX_RUN_S:g}], e.g. 5")
    validate.integer(flooders, "--flooders", lo=1, hi=64, fix="garbage-sending processes in [1, 64], e.g. 1")
    validate.rate(pose_hz, "--pose-hz", hi=1e5, fix="genuine pose packets per second in (0, 1e5], e.g. 1000")
    validate.real(fake_work, "--fake-work", lo=0.0, hi=0.1, unit="s", fix="busy work per fake physics step, e.g. 3e-4")
    validate.integer(max_drain, "--max-drain", lo=1, hi=1_000_000, fix="datagrams per servo tick, e.g. 32")
    validate.real(max_poll_s, "--max-poll-s", lo=0.0, hi=1.0, lo_open=True, unit="s", fix="reading time per tick, e.g. 2e-4")
    validate.real(flood_rate, "--flood-rate", lo=0.0, hi=1e7, fix="datagrams/s per flooder, 0 = as fast as it can")
    validate.real(spin_s, "--spin-s", lo=0.0, hi=0.1, unit="s", fix="polling time before each servo deadline, e.g. 2e-4")
    import sys

    def say(text: str) -> None:      # stage messages, not a bar: redraws would disturb the timed servo
        print(f"bench haptics-flood: {text}", file=sys.stderr, flush=True)

    say("poll cost with garbage queued ...")
    costs = [poll_cost(max_drain, max_poll_s), poll_cost(256, 1.0)]  # this build's bound vs the old one
    say(f"quiet run, {duration:g} s ...")
    quiet = _one_run(duration, 0, pose_hz, scene, fake_work, max_drain, max_poll_s, 0.0, spin_s, priority, servo)
    say(f"flooded run, {duration:g} s, {flooders} flooder(s) ...")
    flooded = _one_run(duration, flooders, pose_hz, scene, fake_work, max_drain, max_poll_s, flood_rate, spin_s, priority, servo)
    return {"poll_cost": costs, "quiet": quiet, "flooded": flooded, "max_drain": max_drain, "max_poll_s": max_poll_s,
            "p99_flooded_over_quiet": flooded["period_p99_ms"] / quiet["period_p99_ms"],
            "flood_rate_limit_per_s": flood_rate,
            "load_avg": list(os.getloadavg()), "cpus": os.cpu_count()}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--duration", type=float, default=5.0, help="s of servo per run; default 5")
    parser.add_argument("--flooders", type=int, default=1, help="garbage-sending processes; default 1")
    parser.add_argument("--pose-hz", type=float, default=1000.0, help="genuine pose packets per second; default 1000")
    parser.add_argument("--scene", action="store_true", help="the palpation scene instead of the fake spring wall")
    parser.add_argument("--fake-work", type=float, default=3e-4, help="s of busy work per fake physics step")
    parser.add_argument("--max-drain", type=int, default=32, help="datagrams read per servo tick at most")
    parser.add_argument("--max-poll-s", type=float, default=2e-4, help="s spent reading per servo tick at most")
    parser.add_argument("--flood-rate", type=float, default=0.0,
                        help="datagrams/s per flooder (0 = as fast as it can; default 0)")
    parser.add_argument("--spin-s", type=float, default=2e-4,
                        help="s before each servo deadline spent polling the clock instead of sleeping; default 2e-4")
    parser.add_argument("--no-priority", action="store_true",
                        help="do not ask for SCHED_FIFO / nice -10 for the servo thread (the old behaviour)")
    parser.add_argument("--servo", choices=("thread", "process"), default="thread",
                        help="servo in a thread of this process (ServoLoop) or in its own process (ProcessServoLoop)")
    parser.add_argument("--json", action="store_true", help="print the JSON rows")


def run(args) -> int:
    res = run_bench(args.duration, args.flooders, args.pose_hz, args.scene, args.fake_work, args.max_drain,
                    args.max_poll_s, args.flood_rate, args.spin_s, not args.no_priority,
                    args.servo)
    if args.json:
        print(json.dumps(res, indent=2))
        return 0
    for c in res["poll_cost"]:
        print(f"poll with {c['queue']} garbage datagrams queued, max_drain {c['max_drain']}, max_poll_s "
              f"{c['max_poll_s']:g}: median {c['poll_median_ms']:.3f} ms, p99 {c['poll_p99_ms']:.3f} ms, "
              f"{c['reads_per_poll_median']:.0f} datagrams read")
    for name in ("quiet", "flooded"):
        r = res[name]
        print(f"{name:<8} period median {r['period_median_ms']:.3f} ms, p99 {r['period_p99_ms']:.3f} ms, "
              f"max {r['period_max_ms']:.2f} ms, overruns {r['overruns']}; poses {r['poses_accepted']}/"
              f"{r['poses_sent']} accepted; flood {r['flood_rate_per_s']:.0f} datagrams/s sent, "
              f"{r['malformed']} malformed read, {r['polls_truncated']} polls truncated; servo {r['scheduling']}")
    print(f"p99 flooded / quiet = {res['p99_flooded_over_quiet']:.2f}")
    print(f"load average {res['load_avg'][0]:.2f} on {res['cpus']} cores")
    return 0
