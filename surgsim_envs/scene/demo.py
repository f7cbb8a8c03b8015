"""``surgsim demo``: a probe palpates a slab with a stiff inclusion, then a three-jaw grasper grasps
and pulls a spleen (the grasping simulation paper's close / hold / pull, time-compressed).

Writes to ``--out`` (default ./surgsim-out/): ``demo.mp4`` (unless --no-video or no OpenGL),
``forces.png`` (normal and tangential force per tool against time) and ``summary.json``;
prints where the files are and the key figures. Headless; needs no arguments.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from surgsim_envs.errors import ConfigError, RenderingUnavailableError
from surgsim_envs.scene.video_overlay import annotate, legend_for

#: default simulated seconds: palpation + grasp (close 1 s, hold 1.5 s, pull 1.5 s)
DEFAULT_DURATION = 7.0
PALPATION_SHARE = 3.0 / 7.0
FPS = 20
#: shadow map size (px) for the demo's video: the scenes ask for 4096, which costs a software
#: rasteriser (Mesa llvmpipe, the usual headless EGL) 44 % of a 640x480 frame (196 -> 109 ms at
#: load 11 on 2 cores) for shadows that look the same at this size
VIDEO_SHADOW_SIZE = 1024
SAMPLE_EVERY = 0.005  # s between force samples


def add_arguments(parser) -> None:
    parser.add_argument("--out", default="surgsim-out", help="output directory (default ./surgsim-out)")
    parser.add_argument("--duration", type=float, default=DEFAULT_DURATION,
                        help=f"simulated seconds for both parts together (default {DEFAULT_DURATION}; 2-60)")
    parser.add_argument("--no-video", action="store_true", help="skip rendering and the MP4")
    parser.add_argument("--camera", default="overview", help="camera name (default overview)")


class _Runner:
    """Steps a simulation, samples forces, renders frames at FPS, times the physics."""

    def __init__(self, sim, renderer, writer, camera, bar, label):
        self.sim, self.renderer, self.writer, self.camera, self.bar = sim, renderer, writer, camera, bar
        self.label = label
        self.caption = ""                # what the video shows now (drawn on every frame)
        self.readout = None              # sample -> text lines drawn at the bottom of the frame
        self.legend = None if renderer is None else legend_for(sim)
        self.samples: list[dict] = []
        self.physics_seconds = 0.0     # steps after the first (rates exclude kernel loading)
        self.physics_steps = 0
        self.first_step_seconds = None
        self._next_frame = 0.0
        self._next_sample = 0.0

    def run(self, duration: float, record) -> None:
        sim = self.sim
        remaining = int(round(duration / sim.dt))  # whole physics steps (a time-based loop can stall on round-off)
        steps_per_frame = max(1, int(round(1.0 / FPS / sim.dt)))
        if remaining > 0 and self.physics_steps == 0 and self.first_step_seconds is None:
            t0 = time.perf_counter()     # the first step loads (or compiles) the kernels: timed apart
            sim.physics_step()
            self.first_step_seconds = time.perf_counter() - t0
            remaining -= 1
            if sim.time >= self._next_sample - 1e-12:
                self.samples.append(record(sim))
                self._next_sample += SAMPLE_EVERY
            if self.bar is not None:
                self.bar.update(min(sim.dt, self.bar.total - self.bar.n))
        while remaining > 0:
            n = min(steps_per_frame, remaining)
            remaining -= n
            t0 = time.perf_counter()
            for _ in range(n):
                sim.physics_step()
                if sim.time >= self._next_sample - 1e-12:
                    self.samples.append(record(sim))
                    self._next_sample += SAMPLE_EVERY
            self.physics_seconds += time.perf_counter() - t0
            self.physics_steps += n
            if self.writer is not None and sim.time >= self._next_frame - 1e-9:
                frame = np.array(self.renderer.render(self.camera))
                lines = self.readout(self.samples[-1]) if self.readout is not None and self.samples else ()
                self.writer.write(annotate(frame, f"t = {sim.time:4.2f} s  {self.caption}", lines, self.legend))
                self._next_frame += 1.0 / FPS
            if self.bar is not None:
                self.bar.update(min(n * sim.dt, self.bar.total - self.bar.n))


def _palpation(sim, runner, duration: float) -> dict:
    """Press above the inclusion, lift, press beside it; return key figures."""
    tissue = sim.tissue()
    top = float(tissue.positions[:, 2].max())
    r = sim.tool("probe").config.tip_radius
    depth = 0.004
    phase = duration / 4.0
    speed = depth / (0.8 * phase) + 1e-9
    xs = (0.0, 0.03)
    peaks = []

    def record(s):
        rep = s.contact_report()["probe"]
        return {"t": s.time, "normal": rep["normal_force"], "tangential": rep["tangential_force"],
                "penetration": rep["penetration"], "z": float(s.tool_position("probe")[2])}

    runner.readout = lambda s: (f"probe force {s['normal']:.3f} N   indentation {1e3 * s['penetration']:.1f} mm",)
    for x, where in zip(xs, ("above the stiff inclusion", "3 cm beside it")):
        above = [x, 0.0, top + r + 0.002]
        sim.set_tool_target("probe", above, speed=math.inf)
        runner.caption = f"palpation: the probe moves {where}"
        runner.run(0.05 * phase, record)
        start = len(runner.samples)
        sim.set_tool_target("probe", [x, 0.0, top + r - depth], speed=speed)
        runner.caption = f"palpation: pressing 4 mm {where}"
        runner.run(phase * 0.95, record)
        pressed = runner.samples[start:]
        peaks.append(max((s["normal"] for s in pressed), default=0.0))
        sim.set_tool_target("probe", above, speed=speed * 2)
        runner.caption = "palpation: the probe lifts; the tissue springs back"
        runner.run(phase, record)
    pen = max((s["penetration"] for s in runner.samples), default=0.0)
    return {"indentation_depth_m": depth, "peak_force_above_inclusion_N": peaks[0],
            "peak_force_beside_inclusion_N": peaks[1], "max_penetration_m": pen,
            "probe_positions_x_m": list(xs)}


def _grasp(sim, runner, duration: float) -> dict:
    """Close, hold, pull (the grasping simulation paper proportions 4 : 7 : pull, compressed); return key figures."""
    g = sim.tool("grasper")
    cfg = g.config
    close_t, hold_t = duration * 0.25, duration * 0.375
    pull_t = duration - close_t - hold_t
    closed = max(cfg.min_radius, 0.012)
    axis = -np.asarray(cfg.axis, dtype=float) / np.linalg.norm(cfg.axis)   # pull direction: out of the organ
    state = {"phase": "close"}

    def record(s):
        rep = s.contact_report()["grasper"]
        jaws = s.jaw_forces("grasper")
        return {"t": s.time, "phase": state["phase"], "normal": rep["normal_force"],
                "tangential": rep["tangential_force"], "contacts": rep["contacts"], "slipping": rep["slipping"],
                "pull_force": float(-s.tool_force("grasper") @ axis), "jaw_normal": jaws["normal"].tolist()}

    runner.readout = lambda s: (f"squeeze (jaw normal forces) {s['normal']:.2f} N   pull {s['pull_force']:.2f} N",
                                f"contact nodes {s['contacts']}   sliding along the jaws {s['slipping']}")
    sim.set_jaw_opening("grasper", closed, speed=(cfg.open_radius - closed) / (0.9 * close_t))
    runner.caption = "grasp: three jaws close on the spleen"
    runner.run(close_t, record)
    state["phase"] = "hold"
    runner.caption = "grasp: hold (the tissue relaxes under the jaws)"
    runner.run(hold_t, record)
    state["phase"] = "pull"
    pull_dist = min(0.05, cfg.travel * 0.9)
    sim.set_tool_target("grasper", g.home + axis * pull_dist, speed=pull_dist / pull_t)
    runner.caption = "grasp: pull; once the pull exceeds friction the tissue slips out (intended)"
    runner.run(pull_t, record)
    pulls = [s for s in runner.samples if s["phase"] == "pull"]
    # gross slip onset as in the grasping simulation paper (Fig. 5, red points): the pull force peaks and then falls
    # as the contact nodes slide along the jaws
    peak_pull = max(pulls, key=lambda s: s["pull_force"]) if pulls else None
    onset = peak_pull if peak_pull is not None and peak_pull["slipping"] > 0 else None
    end_close = [s for s in runner.samples if s["phase"] == "close"]
    end_hold = [s for s in runner.samples if s["phase"] == "hold"]
    return {"closed_radius_m": closed, "pull_distance_m": pull_dist,
            "peak_normal_force_N": max((s["normal"] for s in runner.samples), default=0.0),
            "normal_force_end_of_close_N": end_close[-1]["normal"] if end_close else 0.0,
            "normal_force_end_of_hold_N": end_hold[-1]["normal"] if end_hold else 0.0,
            "peak_pull_force_N": peak_pull["pull_force"] if peak_pull else 0.0,
            "peak_pull_time_s": peak_pull["t"] if peak_pull else None,
            "slip_onset_time_s": onset["t"] if onset else None,
            "slip_onset_pull_force_N": onset["pull_force"] if onset else None,
            "slipping_nodes_at_onset": onset["slipping"] if onset else None,
            "contact_nodes_at_onset": onset["contacts"] if onset else None,
            "phases_s": {"close": close_t, "hold": hold_t, "pull": pull_t}}


def _plot(path: Path, palp: list[dict], grasp: list[dict], grasp_summary: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(8, 6.5))
    ax = axes[0]
    t = [s["t"] for s in palp]
    ax.plot(t, [s["normal"] for s in palp], label="normal")
    ax.plot(t, [s["tangential"] for s in palp], label="tangential")
    ax.set_title("Probe palpating a liver slab with a stiff inclusion")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("force (N)")
    ax.legend()
    ax = axes[1]
    t = [s["t"] for s in grasp]
    ax.plot(t, [s["normal"] for s in grasp], label="normal (3 jaws)")
    ax.plot(t, [s["tangential"] for s in grasp], label="tangential (3 jaws)")
    ax.plot(t, [s["pull_force"] for s in grasp], ":", label="pull force (along axis)")
    for key, phase in (("close", "close"), ("hold", "hold")):
        ends = [s["t"] for s in grasp if s["phase"] == phase]
        if ends:
            ax.axvline(ends[-1], color="grey", lw=0.8)
    if grasp_summary.get("slip_onset_time_s") is not None:
        ax.plot([grasp_summary["slip_onset_time_s"]], [grasp_summary["slip_onset_pull_force_N"]], "ro",
                label="gross slip onset")
    ax.set_title("Three-jaw grasper: close, hold, pull (the grasping simulation paper, time-compressed)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("force (N)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


#: simulated seconds of the warm-up schedule: the demo's own press, grasp and pull, shortened
WARMUP_DURATION = 2.0
STAGE_NAMES = {"palpation": "demo: palpation scene", "grasp": "demo: grasp scene"}
_PARTS = {"palpation": (_palpation, PALPATION_SHARE), "grasp": (_grasp, 1 - PALPATION_SHARE)}


def _scene(name: str):
    from surgsim_envs.scene.builder import grasp_scene, palpation_scene

    return {"palpation": palpation_scene, "grasp": grasp_scene}[name]()


def warmup_stages(sims: dict | None = None) -> list:
    """The demo's warm-up: per part, its scene runs the demo schedule shortened to
    WARMUP_DURATION (every kernel the demo calls, with the same argument types), syncs the
    render twin, then goes back to its initial state. ``sims`` (part -> Simulation) reuses the
    demo's simulations; None builds them."""
    from surgsim_envs.scene.kernel_warmup import Stage

    def stage(name):
        def run():
            from surgsim_envs.scene.simulation import Simulation

            sim = sims[name] if sims is not None else Simulation(_scene(name))
            fn, share = _PARTS[name]
            fn(sim, _Runner(sim, None, None, None, None, name), WARMUP_DURATION * share)
            sim.sync_visual()
            sim.reset()
        return Stage(STAGE_NAMES[name], run)

    return [stage(name) for name in _PARTS]


def _compile_if_cold(sims: dict) -> float:
    """Compile the demo's kernels ahead, under a progress bar, when the caches are cold; returns
    the seconds spent (0 when warm)."""
    from surgsim_envs.numba_cache import is_warm
    from surgsim_envs.scene.kernel_warmup import run_stages

    cold = [name for name in _PARTS if is_warm(STAGE_NAMES[name]) is False]
    if not cold:
        return 0.0
    print("surgsim demo: first run here: compiling the physics kernels once (numba; about 30-40 s on two cores); "
          "later runs load them from the cache. `surgsim warmup` does this ahead.", flush=True)
    t0 = time.perf_counter()
    stages = [st for st in warmup_stages(sims) if st.name in {STAGE_NAMES[n] for n in cold}]
    run_stages(stages, desc="surgsim demo: compiling")
    return time.perf_counter() - t0


def run(args) -> int:
    from tqdm import tqdm

    from surgsim_envs.scene.render import SceneRenderer, VideoWriter
    from surgsim_envs.scene.simulation import Simulation

    duration = float(args.duration)
    if not (math.isfinite(duration) and 2.0 <= duration <= 60.0):
        raise ConfigError(f"--duration {args.duration!r} s is out of range; give 2-60 s (default {DEFAULT_DURATION})")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    wall0 = time.perf_counter()
    sims = {name: Simulation(_scene(name)) for name in _PARTS}
    compile_seconds = _compile_if_cold(sims)
    renderers, writer, video_note = {}, None, None
    if not args.no_video:
        try:
            for name, sim in sims.items():
                sim.render_model.vis.quality.shadowsize = min(VIDEO_SHADOW_SIZE, sim.render_model.vis.quality.shadowsize)
                renderers[name] = SceneRenderer(sim, 640, 480)
            writer = VideoWriter(out / "demo.mp4", FPS, (640, 480))
        except RenderingUnavailableError as exc:
            renderers, writer, video_note = {}, None, str(exc)
            print(f"surgsim demo: no video: {exc}")
    durations = {"palpation": duration * PALPATION_SHARE, "grasp": duration * (1 - PALPATION_SHARE)}
    summary: dict = {"duration_s": duration, "compile_seconds": compile_seconds}
    samples = {}
    with tqdm(total=round(duration, 6), mininterval=0.5, unit="sim s", bar_format="{l_bar}{bar}| {n:.2f}/{total:.2f} sim s [{elapsed}]") as bar:
        for name, (fn, _) in _PARTS.items():
            sim = sims[name]
            runner = _Runner(sim, renderers.get(name), writer, args.camera, bar, name)
            if writer is not None and args.camera not in renderers[name].cameras:
                raise ConfigError(f"unknown camera {args.camera!r}; cameras: {renderers[name].cameras}")
            figures = fn(sim, runner, durations[name])
            figures["physics_steps"] = runner.physics_steps
            figures["dt_s"] = sim.dt
            figures["physics_steps_per_second"] = runner.physics_steps / max(runner.physics_seconds, 1e-9)
            figures["first_step_seconds"] = runner.first_step_seconds     # kernel loading: not in the rate
            figures["tissue_nodes"] = int(sim.tissue().n_nodes)
            figures["tissue_model"] = sim.tissue().name
            summary[name] = figures
            samples[name] = runner.samples
    if writer is not None:
        writer.close()
    for r in renderers.values():
        r.close()
    plot_path = out / "forces.png"
    _plot(plot_path, samples["palpation"], samples["grasp"], summary["grasp"])
    summary["wall_time_s"] = time.perf_counter() - wall0
    summary["files"] = {"video": str(out / "demo.mp4") if writer is not None else None, "plot": str(plot_path),
                        "summary": str(out / "summary.json")}
    if video_note:
        summary["video_unavailable"] = video_note
    with open(out / "summary.json", "w") as fh:
        json.dump(summary, fh, indent=2, default=float)
    from surgsim_envs.numba_cache import mark_warm

    mark_warm(STAGE_NAMES.values())      # every kernel the demo calls is in the caches now
    p, g = summary["palpation"], summary["grasp"]
    print(f"surgsim demo: wrote {', '.join(v for v in summary['files'].values() if v)}")
    print(f"  palpation: peak force {p['peak_force_above_inclusion_N']:.3f} N above the inclusion vs "
          f"{p['peak_force_beside_inclusion_N']:.3f} N beside it (indentation {p['indentation_depth_m'] * 1e3:.0f} mm, "
          f"max penetration {p['max_penetration_m'] * 1e3:.2f} mm); "
          f"{p['physics_steps_per_second']:.0f} physics steps/s ({p['tissue_nodes']} nodes, dt {p['dt_s'] * 1e3:g} ms)")
    onset = ("no gross slip" if g["slip_onset_time_s"] is None else
             f"gross slip at t={g['slip_onset_time_s']:.2f} s, pull force {g['slip_onset_pull_force_N']:.3f} N")
    print(f"  grasp: peak normal force {g['peak_normal_force_N']:.3f} N (end of close {g['normal_force_end_of_close_N']:.3f} N"
          f" -> end of hold {g['normal_force_end_of_hold_N']:.3f} N, relaxation); peak pull {g['peak_pull_force_N']:.3f} N; "
          f"{onset}; {g['physics_steps_per_second']:.0f} physics steps/s ({g['tissue_nodes']} nodes)")
    compiled = f" ({compile_seconds:.1f} s compiling kernels, once)" if compile_seconds else ""
    print(f"  wall time {summary['wall_time_s']:.1f} s{compiled}; physics rates exclude kernel compilation and loading")
    return 0
