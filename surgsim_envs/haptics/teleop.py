"""``surgsim teleop TASK --device ...``: teleoperate a task with a (simulated) haptic device.

    surgsim teleop palpation --device scripted --headless --out out/ --duration 3
    surgsim teleop grasp --device replay:hand.csv --headless --out out/
    surgsim teleop palpation --device keyboard            # interactive viewer (needs a display)
    surgsim teleop slippage --device udp:9870             # poses from a remote device on 127.0.0.1

The servo loop runs at ``--rate`` (1 kHz) in its own thread, the physics in another; the device
frame's origin is the tool's home pose. With a viewer the scene is shown in real time; with
``--headless`` it writes ``teleop_TASK.mp4`` (offscreen rendering), ``force_log.csv`` (the force
the hand felt, ``t,fx,fy,fz,saturated``) and ``stats.json`` into ``--out``. Loop statistics are
printed at the end. The MuJoCo scene is imported only when the command runs.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

from surgsim_envs.errors import ConfigError, SurgSimError
from surgsim_envs.haptics.teleop_args import check_camera, check_device_duration, check_teleop_args

TASK_NAMES = ("palpation", "grasp", "slippage")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from surgsim_envs.haptics.keyboard import key_help

    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = ("--device keyboard (in the viewer window; also shown in its top-left corner):\n" + key_help()
                     + "\n\nWithout a display, run headless with a device that needs no window: scripted, "
                       "replay:FILE or udp:PORT\n(e.g. surgsim teleop palpation --device scripted --headless); "
                       "the keyboard needs a (virtual) display: xvfb-run -a surgsim teleop ...")
    parser.add_argument("task", choices=TASK_NAMES, help="task to teleoperate")
    parser.add_argument("--device", default="scripted",
                        help="scripted | replay:FILE (.csv/.json) | keyboard | udp:PORT (default scripted)")
    parser.add_argument("--script", default=None, help="scripted device: JSON/TOML trajectory spec (default: a task demo)")
    parser.add_argument("--headless", action="store_true", help="no viewer: write video + force log to --out")
    parser.add_argument("--out", default="surgsim-out/teleop", help="output directory (headless)")
    parser.add_argument("--duration", type=float, default=None,
                        help="seconds to run (default: the script/recording length; live devices: until the "
                             "viewer closes, 10 s headless)")
    parser.add_argument("--rate", type=float, default=1000.0, help="servo rate, Hz (default 1000)")
    parser.add_argument("--extrapolation", choices=("hold", "linear", "stiffness"), default="linear",
                        help="force extrapolation between physics updates (default linear)")
    parser.add_argument("--max-force", type=float, default=3.3, help="device force limit, N (default 3.3)")
    parser.add_argument("--max-force-rate", type=float, default=1000.0, help="force rate clamp, N/s (default 1000)")
    parser.add_argument("--spacing", type=float, default=None, help="tissue node spacing, m (default: the scene's)")
    parser.add_argument("--model", default="mass_spring", help="tissue model (surgsim models), default mass_spring")
    parser.add_argument("--seed", type=int, default=0, help="seed of the scripted tremor/drift")
    parser.add_argument("--tremor", type=float, default=0.0, help="scripted tremor amplitude, m (8-12 Hz)")
    parser.add_argument("--fps", type=float, default=25.0, help="video/viewer frames per second")
    parser.add_argument("--size", type=int, nargs=2, default=(480, 360), metavar=("W", "H"), help="video size, pixels")
    parser.add_argument("--camera", default="overview", help="camera name for the video")
    parser.add_argument("--panels", action="store_true",
                        help="show MuJoCo's viewer side panels (hidden by default; Tab toggles them)")
    parser.add_argument("--servo", choices=("auto", "thread", "process"), default="auto",
                        help="auto (default): process for udp devices, thread otherwise; thread: the servo in "
                             "this process; process: in its own process with real-time priority (udp devices "
                             "only; p99 <= 1.2 ms with its port flooded, docs/haptics.md)")


def parse_device(spec: str):
    """``"scripted"`` / ``"replay:FILE"`` / ``"keyboard"`` / ``"udp:PORT"`` -> (DeviceKind, argument)
    (:func:`surgsim_envs.haptics.device_kinds.device_kind`, the one parser; a named file must exist)."""
    from surgsim_envs.haptics.device_kinds import device_kind

    kind, arg = device_kind(spec)
    if kind.file_arg and not Path(arg).is_file():
        raise ConfigError(f"--device {spec}: file not found; give a .csv or .json pose recording")
    return kind, arg


def default_script(task: str, physics, seed: int = 0, tremor: float = 0.0) -> dict:
    """A demonstration trajectory (device frame, origin at the tool's home) for ``task``."""
    extra = {"seed": seed, "tremor_amplitude": tremor, "profile": "minimum_jerk"}
    if task == "palpation":
        from surgsim_envs.haptics.scene_adapter import tissue_top

        tip = float(physics.tool.config.tip_radius)
        gap = physics.home_position[2] - tip - tissue_top(physics)  # m to first contact
        down = -(max(gap, 0.0) + 0.006)
        return {"waypoints": [[0, 0, 0], [0, 0, down], [0.01, 0, down], [0, 0, 0]], "speeds": [0.01, 0.005, 0.01],
                "dwell": [0.2, 0.5, 0.3, 0.2], **extra}
    pull = 0.02 if task == "grasp" else 0.03
    grip = 0.8 if task == "grasp" else 0.45
    speed = 0.01 if task == "grasp" else 0.02
    return {"waypoints": [[0, 0, 0], [0, 0, 0], [pull, 0, 0], [pull, 0, 0]], "speeds": [1.0, speed, 1.0],
            "dwell": [0.2, 3.0, 0.5, 0.0], "grip": [0.0, grip, grip, grip], **extra}


def load_script(path: str) -> dict:
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"--script {path}: file not found")
    suffix = p.suffix.lower()
    if suffix in (".json", ".toml"):
        import tomllib

        try:
            data = json.loads(p.read_text()) if suffix == ".json" else tomllib.loads(p.read_text())
        except (ValueError, UnicodeDecodeError) as exc:    # JSONDecodeError, TOMLDecodeError
            raise ConfigError(f"--script {path}: not valid {suffix[1:].upper()}: {exc}") from None
        if suffix == ".toml":
            data = data.get("trajectory", data)
        if not isinstance(data, dict):
            raise ConfigError(f"--script {path}: expected a trajectory object (waypoints, speeds, ...), got "
                              f"{type(data).__name__}")
        return data
    raise ConfigError(f"--script {path}: expected a .json or .toml trajectory spec")


def make_device(args, physics, limits):
    """Build the device named on the command line (:func:`surgsim_envs.haptics.device_kinds.make_device`;
    "scripted" plays ``--script`` or the task's demonstration trajectory)."""
    from surgsim_envs.haptics.device_kinds import make_device as make
    from surgsim_envs.haptics.scripted import ScriptedDevice, TrajectorySpec

    def scripted():
        spec = load_script(args.script) if args.script else default_script(args.task, physics, args.seed, args.tremor)
        return ScriptedDevice(TrajectorySpec.from_dict(spec), limits=limits)

    return make(args.device, limits=limits, scripted=scripted)


def run(args) -> int:
    from surgsim_envs.haptics.device import DeviceLimits
    from surgsim_envs.haptics.servo import DeviceMapping, ServoConfig, ServoLoop

    kind, arg = parse_device(args.device)
    servo = getattr(args, "servo", "auto")
    if servo == "auto":  # the servo owns a network device in its own process: no shared GIL (docs/haptics.md)
        servo = "process" if kind.remote else "thread"
    if servo == "process" and not kind.remote:
        raise ConfigError(f"--servo process needs a network device (--device udp:PORT): the servo process owns "
                          f"the device; got --device {args.device}. Use --servo thread for it.")
    check_teleop_args(args)
    if args.script:                      # a malformed or endless script is refused before the scene is built
        from surgsim_envs.haptics.scripted import TrajectorySpec

        spec = TrajectorySpec.from_dict(load_script(args.script))
        if args.duration is None and kind.finite:
            check_device_duration(spec, args.device)
    no_display = not os.environ.get("DISPLAY") and sys.platform.startswith("linux")
    if kind.needs_viewer and (args.headless or no_display):
        why = "--headless has no window" if args.headless else "there is no display ($DISPLAY is not set)"
        print(f"surgsim teleop: --device {args.device} reads its keys from the viewer window, and {why}.\n"
              f"Run it under a display (or a virtual one: xvfb-run -a surgsim teleop {args.task} --device "
              f"{args.device}), or teleoperate headless with a device that needs no window, e.g.:\n"
              f"  surgsim teleop {args.task} --device scripted --headless --out surgsim-out/teleop --duration 5\n"
              "(also replay:FILE or udp:PORT)", file=sys.stderr)
        return 2
    if not args.headless and no_display:
        print("surgsim teleop: no display ($DISPLAY is not set), so the interactive viewer cannot open.\n"
              f"Run headless instead, e.g.: surgsim teleop {args.task} --device {args.device} --headless "
              "--out surgsim-out/teleop --duration 5", file=sys.stderr)
        return 2
    try:
        from surgsim_envs.haptics import scene_adapter
    except ImportError as exc:
        raise SurgSimError(f"teleop needs the MuJoCo scene (surgsim_envs.scene), which is unavailable: {exc}") from None

    from surgsim_envs.haptics.realtime import fifo_notice

    notice = fifo_notice()
    if notice:
        print(f"surgsim teleop: {notice}", flush=True)
    print(f"building the {args.task} scene ...", flush=True)
    physics = scene_adapter.make_haptic_simulation(args.task, spacing=args.spacing, model=args.model)
    _compile_kernels(physics, args.task)
    limits = DeviceLimits(max_force=args.max_force)
    if servo == "process":
        return _run_process_servo(args, arg, physics, limits)
    device = make_device(args, physics, limits)
    duration = args.duration
    if duration is None:
        if kind.finite:
            duration = check_device_duration(device, args.device) + 0.2
        else:  # live devices: until the viewer closes; headless needs a bound
            duration = 10.0 if args.headless else math.inf
    config = ServoConfig(rate_hz=args.rate, max_force_rate=args.max_force_rate, extrapolation=args.extrapolation,
                         mapping=DeviceMapping(origin=tuple(physics.home_position)))
    with device:
        if kind.remote:
            print(f"listening for pose packets on udp://{device.address[0]}:{device.address[1]}", flush=True)
        loop = ServoLoop(device, physics, config)
        if args.headless:
            stats = _run_headless(loop, physics, args, duration)
        else:
            stats = _run_viewer(loop, physics, device, duration, panels=getattr(args, "panels", False))
    print(stats.summary())
    if device.session_summary():
        print(device.session_summary(), flush=True)
    if args.headless:
        out = Path(args.out)
        device.force_log.to_csv(out / "force_log.csv")
        (out / "stats.json").write_text(json.dumps({"task": args.task, "device": args.device, **stats.as_dict()}, indent=2))
        print(f"wrote {out / f'teleop_{args.task}.mp4'}, {out / 'force_log.csv'}, {out / 'stats.json'}")
    return 0


def _compile_kernels(physics, task: str) -> None:
    """Compile the scene's kernels before the servo starts (a warm-up press, then a reset): on a
    cold cache the first press would otherwise stall the physics for tens of seconds while the
    servo and the viewer run. Under a progress bar when the caches are cold or elsewhere."""
    from surgsim_envs.haptics.scene_adapter import warm_up
    from surgsim_envs.numba_cache import is_warm
    from surgsim_envs.scene.kernel_warmup import Stage, run_stages

    stage = Stage(f"teleop: {task}", lambda: warm_up(physics))
    cold = is_warm(stage.name) is not True
    if cold:
        print("surgsim teleop: compiling the physics kernels before the session starts (numba, once per "
              "install; later sessions load them from the cache)", flush=True)
    run_stages([stage], desc="surgsim teleop: compiling", progress=cold)


def _config(args, physics):
    from surgsim_envs.haptics.servo import DeviceMapping, ServoConfig

    return ServoConfig(rate_hz=args.rate, max_force_rate=args.max_force_rate, extrapolation=args.extrapolation,
                       mapping=DeviceMapping(origin=tuple(physics.home_position)))


def _run_process_servo(args, port, physics, limits) -> int:
    """``--servo process``: the UDP device and the 1 kHz servo in a child process
    (:class:`~surgsim_envs.haptics.servo_process.ProcessServoLoop`), the scene in this one."""
    import functools

    from surgsim_envs.haptics.servo_process import ProcessServoLoop
    from surgsim_envs.haptics.udp_bridge import UdpDevice

    duration = args.duration if args.duration is not None else (10.0 if args.headless else math.inf)
    loop = ProcessServoLoop(functools.partial(UdpDevice, port=int(port), limits=limits), physics,
                            _config(args, physics))
    print(f"listening for pose packets on udp://127.0.0.1:{port} (servo process)", flush=True)
    stats = _run_headless(loop, physics, args, duration) if args.headless else \
        _run_viewer(loop, physics, None, duration, panels=getattr(args, "panels", False))
    print(stats.summary())
    print(f"bridge: {loop.device_stats}")
    if args.headless:
        out = Path(args.out)
        loop.force_log.to_csv(out / "force_log.csv")
        (out / "stats.json").write_text(json.dumps({"task": args.task, "device": args.device, "servo": "process",
                                                    **stats.as_dict(), "bridge": loop.device_stats}, indent=2))
        print(f"wrote {out / f'teleop_{args.task}.mp4'}, {out / 'force_log.csv'}, {out / 'stats.json'}")
    return 0


def _run_headless(loop, physics, args, duration: float):
    import mujoco

    from surgsim_envs.errors import RenderingUnavailableError

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sim = physics.sim
    width, height = int(args.size[0]), int(args.size[1])
    cameras = [mujoco.mj_id2name(sim.model, mujoco.mjtObj.mjOBJ_CAMERA, i) for i in range(sim.model.ncam)]
    check_camera(args.camera, cameras)
    try:
        renderer = mujoco.Renderer(sim.render_model, height=height, width=width)
    except Exception as exc:
        raise RenderingUnavailableError(
            f"offscreen rendering failed ({exc}); set MUJOCO_GL=egl or MUJOCO_GL=osmesa (apt-get install libosmesa6)"
        ) from None
    cam = args.camera
    scratch = mujoco.MjData(sim.render_model)
    path = out / f"teleop_{args.task}.mp4"
    from surgsim_envs.haptics.recording import PacedVideoWriter
    from surgsim_envs.scene.media import VideoWriter

    # H.264 with the [media] extra (imageio-ffmpeg), else mp4v with a warning (scene/media.py)
    writer = PacedVideoWriter(VideoWriter(path, float(args.fps), (width, height)), float(args.fps))

    def frame(_loop) -> None:
        with _loop.physics_lock:  # copy the state briefly; render outside the lock
            mujoco.mj_copyData(scratch, sim.render_model, sim.sync_visual())
        renderer.update_scene(scratch, camera=cam)
        writer.write(renderer.render().copy())      # RGB; the renderer reuses its buffer

    try:
        stats = loop.run_realtime(duration, on_frame=frame, frame_period=1.0 / args.fps)
    finally:
        writer.close(loop.stats.duration_s or None)  # pad to the run's wall-clock length
        renderer.close()
    return stats


def _run_viewer(loop, physics, device, duration: float, panels: bool = False):  # pragma: no cover - needs a display
    from surgsim_envs.scene.display import close_viewer, frame_tissue, open_viewer, require_display

    require_display("surgsim teleop (viewer)")   # raises; MuJoCo would exit the process
    sim = physics.sim
    callback = getattr(device, "key_callback", None)   # devices that read the viewer's keys
    help_text = None
    if callback is not None:
        from surgsim_envs.haptics.keyboard import key_help, key_overlay

        help_text = key_overlay()
        print("keys (in the viewer window):\n" + key_help(), flush=True)
    viewer = open_viewer(sim.render_model, sim.sync_visual(), key_callback=callback, panels=panels,
                         help_text=help_text)
    frame_tissue(viewer, sim)   # free camera on the tissue (the default frames the whole floor)
    try:
        def frame(_loop):
            if not viewer.is_running():
                return False
            with _loop.physics_lock:
                sim.sync_visual()
                viewer.sync()
            return True

        stats = loop.run_realtime(duration if math.isfinite(duration) else 1e9, on_frame=frame, frame_period=1 / 60)
    finally:
        close_viewer(viewer)  # wait for the window thread: exiting under it segfaults in glfw.terminate
    return stats
