"""``surgsim bench haptics``: period of the 1 kHz haptic servo loop with a tissue in contact.

The servo thread (1 kHz, absolute deadlines) and the physics thread (as fast as it can, never
ahead of the wall clock) run together for ``--duration`` s while a scripted hand holds the probe
pressed ``--depth`` m into a ~1,000-node liver slab (palpation scene, proxy-driven probe). The
servo's wall-clock periods give the median and p99; the physics update rate is reported too.

Without the MuJoCo scene (or with ``--fake``) the physics is the analytic spring wall
(:class:`~surgsim_envs.haptics.fake_physics.SpringWallPhysics`) with ``--fake-work`` s of
busy work per step to stand in for the tissue; the output then says ``"fake_physics": true``.
Timings depend on the machine and its load; no test asserts them.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from surgsim_envs import validate

#: slab organ at this spacing: 17 x 17 x 4 = 1,156 nodes (a node under the probe axis)
SCENE_SPACING = 0.00625


def _build_physics(fake: bool, fake_work: float):
    """(physics, description dict, surface z of first contact for the probe centre)."""
    if not fake:
        try:
            from surgsim_envs.haptics import scene_adapter
        except ImportError as exc:
            print(f"bench haptics: scene unavailable ({exc}); using the fake spring-wall physics", file=sys.stderr)
        else:
            phys = scene_adapter.make_haptic_simulation("palpation", spacing=SCENE_SPACING, organ="slab")
            contact_z = scene_adapter.tissue_top(phys) + float(phys.tool.config.tip_radius)
            info = {"physics": "scene:palpation/slab", "fake_physics": False, "n_nodes": int(phys.sim.tissue().n_nodes)}
            return phys, info, contact_z, phys.home_position.copy()
    from surgsim_envs.haptics.fake_physics import SpringWallPhysics

    phys = SpringWallPhysics(start_position=(0.0, 0.0, 0.005), work_seconds=fake_work)
    info = {"physics": "fake_spring_wall", "fake_physics": True, "n_nodes": 0, "fake_work_s": fake_work}
    return phys, info, 0.0, np.array([0.0, 0.0, 0.005])


def run_bench(duration: float = 3.0, depth: float = 0.004, fake: bool = False, fake_work: float = 3e-4,
              extrapolation: str = "linear", rate_hz: float = 1000.0) -> dict:
    """Run the threaded servo with the probe in contact; returns the JSON row."""
    from surgsim_envs.haptics import DeviceLimits, DeviceMapping, ScriptedDevice, ServoConfig, ServoLoop, TrajectorySpec

    validate.duration(duration, "--duration", hi=600.0, fix="seconds of servo in (0, 600], e.g. 3")
    validate.real(depth, "--depth", lo=0.0, hi=0.02, lo_open=True, unit="m", fix="a press depth in (0, 0.02] m, e.g. 0.004")
    validate.rate(rate_hz, "--rate", hi=1e5, fix="a servo rate in (0, 1e5] Hz, e.g. 1000")
    validate.real(fake_work, "--fake-work", lo=0.0, hi=0.1, unit="s", fix="busy work per fake physics step, e.g. 3e-4")
    phys, info, contact_z, home = _build_physics(fake, fake_work)
    bottom = contact_z - depth - home[2]  # device frame (origin at home)
    mapping = DeviceMapping(origin=tuple(home))
    limits = DeviceLimits(max_force=10.0)
    # 1) press into contact on the simulated clock (also compiles numba kernels); no progress bar in
    # the timed part: its redraws would share the GIL with the servo it measures
    import sys

    print(f"bench haptics: pressing into contact (the first run compiles kernels), then {duration:g} s held "
          "on the wall clock ...", file=sys.stderr, flush=True)
    approach = ScriptedDevice(TrajectorySpec(waypoints=[[0, 0, 0], [0, 0, bottom]], speeds=0.02, dwell=[0.0, 0.3],
                                             profile="minimum_jerk"), limits=limits)
    with approach:
        ServoLoop(approach, phys, ServoConfig(rate_hz=rate_hz, mapping=mapping)).run_simulated(approach.duration)
    # 2) hold in contact on the wall clock with the threads
    hold = ScriptedDevice(TrajectorySpec(waypoints=[[0, 0, bottom]], dwell=duration + 1.0), limits=limits)
    with hold:
        loop = ServoLoop(hold, phys, ServoConfig(rate_hz=rate_hz, extrapolation=extrapolation, mapping=mapping))
        stats = loop.run_realtime(duration, frame_period=0.05)
        felt = hold.force_log.magnitudes
    return {
        "period_median_ms": stats.period_median_ms,
        "period_p99_ms": stats.period_p99_ms,
        "period_max_ms": stats.period_max_ms,
        "physics_rate_hz": stats.physics_rate_hz,
        "servo_rate_hz": rate_hz,
        "physics_dt_s": float(phys.dt),
        "overruns": stats.overruns,
        "ticks": stats.ticks,
        "duration_s": stats.duration_s,
        "extrapolation": extrapolation,
        "depth_m": depth,
        "median_force_n": float(np.median(felt)) if len(felt) else 0.0,
        **info,
    }


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--duration", type=float, default=3.0, help="seconds of threaded servo loop (default 3)")
    parser.add_argument("--depth", type=float, default=0.004, help="press depth into the tissue, m (default 0.004)")
    parser.add_argument("--rate", type=float, default=1000.0, help="servo rate, Hz (default 1000)")
    parser.add_argument("--extrapolation", choices=("hold", "linear", "stiffness"), default="linear")
    parser.add_argument("--fake", action="store_true", help="use the fake spring-wall physics even if the scene exists")
    parser.add_argument("--fake-work", type=float, default=3e-4, help="busy work per fake physics step, s (default 3e-4)")


def run(args: argparse.Namespace) -> int:
    row = run_bench(args.duration, args.depth, args.fake, args.fake_work, args.extrapolation, args.rate)
    if args.json:
        print(json.dumps(row, indent=2))
    else:
        flag = "  [FAKE physics: spring wall, not the tissue scene]" if row["fake_physics"] else ""
        print(f"haptic servo at {row['servo_rate_hz']:.0f} Hz with {row['physics']} ({row['n_nodes']} nodes) in contact{flag}\n"
              f"  period median {row['period_median_ms']:.3f} ms, p99 {row['period_p99_ms']:.3f} ms, "
              f"max {row['period_max_ms']:.3f} ms, overruns {row['overruns']}\n"
              f"  physics {row['physics_rate_hz']:.0f} updates/s (dt {row['physics_dt_s'] * 1e3:.2f} ms), "
              f"median felt force {row['median_force_n']:.3f} N")
    return 0
