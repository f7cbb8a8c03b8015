"""Checks of ``surgsim teleop``'s flags, run before the scene is built: each bad value is refused
with its flag, the bound and the fix, and every loop the command starts has an end that fits the
machine (the servo and frame rates, the run length, the video size)."""

from __future__ import annotations

import math

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError

#: Hz, the fastest video / viewer frame rate (a frame is a full offscreen render)
MAX_FPS = 240.0
#: Hz, the fastest haptic servo loop (1 kHz is the haptic standard)
MAX_SERVO_HZ = 10_000.0
#: s, the longest teleoperation run (real time: the run takes this long on the wall clock)
MAX_TELEOP_SECONDS = validate.MAX_SIM_SECONDS
#: px, the video frame sides
VIDEO_PX = (16, 4096)
#: m, the largest scripted tremor amplitude (physiological hand tremor is about 0.1 mm)
MAX_TREMOR_M = 0.01
#: m, tissue node spacings a teleop scene accepts (finer: millions of nodes, no real-time servo)
SPACING_RANGE_M = (0.002, 0.05)


def check_teleop_args(args) -> None:
    """ConfigError naming the first bad flag of parsed ``surgsim teleop`` arguments."""
    validate.seed(args.seed, "--seed")
    w, h = args.size
    for name, v in (("--size W", w), ("--size H", h)):
        validate.integer(v, name, lo=VIDEO_PX[0], hi=VIDEO_PX[1], unit="px",
                         fix=f"video frames are {VIDEO_PX[0]}..{VIDEO_PX[1]} px per side, e.g. --size 480 360")
    validate.rate(args.fps, "--fps", hi=MAX_FPS, fix=f"a frame rate in (0, {MAX_FPS:g}] Hz, e.g. 25")
    validate.rate(args.rate, "--rate", hi=MAX_SERVO_HZ, fix=f"a servo rate in (0, {MAX_SERVO_HZ:g}] Hz, e.g. 1000")
    if args.duration is not None:
        check_teleop_duration(args.duration, "--duration")
    validate.real(args.tremor, "--tremor", lo=0.0, hi=MAX_TREMOR_M, unit="m",
                  fix=f"a tremor amplitude in [0, {MAX_TREMOR_M:g}] m (hand tremor is about 1e-4 m)")
    validate.positive(args.max_force, "--max-force", hi=1e3, unit="N", fix="a device force limit, e.g. 3.3 N")
    validate.positive(args.max_force_rate, "--max-force-rate", hi=1e7, unit="N/s", fix="e.g. 1000 N/s")
    if args.spacing is not None:
        validate.real(args.spacing, "--spacing", lo=SPACING_RANGE_M[0], hi=SPACING_RANGE_M[1], unit="m",
                      fix=f"a node spacing in [{SPACING_RANGE_M[0]:g}, {SPACING_RANGE_M[1]:g}] m (finer lattices "
                          "cannot run the servo in real time)")
    validate.text(args.camera, "--camera", fix="a camera name of the scene, e.g. overview")


def check_teleop_duration(seconds: float, what: str) -> float:
    """A teleoperation run length in (0, MAX_TELEOP_SECONDS] s (it runs in real time)."""
    return validate.duration(seconds, what, hi=MAX_TELEOP_SECONDS,
                             fix=f"teleoperation runs in real time; at most {MAX_TELEOP_SECONDS:g} s, or give "
                                 "--duration to cut a longer script or recording")


def check_device_duration(device, spec: str) -> float:
    """The run length of a finite device (a script or recording) without ``--duration``."""
    seconds = float(device.duration)
    if not math.isfinite(seconds) or seconds > MAX_TELEOP_SECONDS:
        raise ConfigError(f"--device {spec} lasts {seconds:g} s, above the {MAX_TELEOP_SECONDS:g} s a teleoperation "
                          "run may take (it runs in real time); pass --duration to play only its start, or fix "
                          "the times in the script or recording")
    return seconds


def check_camera(name: str, cameras: list[str]) -> None:
    """``--camera`` must name a camera of the scene."""
    if name not in cameras:
        raise ConfigError(f"--camera {name!r} is not a camera of this scene; cameras: {cameras}")
