"""Run a scenario: build its scene, drive its phases (script, device or policy), record forces.

>>> from surgsim_envs.scenarios import load_scenario, run_scenario
>>> sc = load_scenario("tasks/spleen_grasp_and_retract.toml")            # doctest: +SKIP
>>> results = run_scenario(sc, duration_scale=0.25, progress=False)      # doctest: +SKIP
>>> results[0].score, results[0].metrics["peak_force"]                    # doctest: +SKIP

Every physics step the active phase's driver gives a command: a tool offset (3,) m from the
tool's home and a jaw opening (m). The script driver takes it from the phase
(:mod:`~surgsim_envs.scenarios.phases`); a device driver from a
:class:`~surgsim_envs.haptics.HapticDevice` (position in m relative to the home pose, grip 0..1
mapped to open..min jaw opening; the tissue force on the tool is sent back to it); a policy
driver from a callable ``policy(obs: dict) -> {"offset": (3,), "opening": m}`` evaluated every
``CONTROL_PERIOD`` s. Samples are recorded every ``scenario.sample_period`` s. The MuJoCo scene
is imported only when a scenario runs. Units: m, s, N.
"""

from __future__ import annotations

import copy
import math
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from surgsim_envs.errors import ConfigError, RenderingUnavailableError, TissueUnstableError
from surgsim_envs.scenarios.phases import SCENE_TOOL, PhaseContext
from surgsim_envs.scenarios.recording import Recording, RunResult
from surgsim_envs.scenarios.schema import Scenario
from surgsim_envs.scenarios.policies import policy_for

CONTROL_PERIOD = 0.01  # s between policy evaluations in phase scenarios
FPS = 25


# ----------------------------------------------------------------------------------------------
# Scene
def scene_config(sc: Scenario):
    """The :class:`~surgsim_envs.scene.SceneConfig` of a scenario (ready-made scene + overrides)."""
    from surgsim_envs.scene import scene_config as ready_made

    o = sc.scene
    organ = o.organ
    if isinstance(organ, str) and Path(organ).suffix:            # a mesh file, relative to the scenario
        from surgsim_envs.scenarios.schema import resolve_data_file

        organ = str(resolve_data_file(organ, getattr(sc, "folder", None)))
    kw = {k: v for k, v in (("organ", organ), ("model", o.model)) if v is not None}
    cfg = ready_made(sc.meta.scene, **kw)
    tissue = cfg.tissues[0]
    if o.material is not None:
        tissue.material = o.material
    if o.spacing is not None:
        tissue.spacing = float(o.spacing)
    if o.dt is not None:
        cfg.dt = float(o.dt)
    if o.inclusion_xy is not None:
        if tissue.organ != "slab_inclusion":
            raise ConfigError(f"scene.inclusion_xy needs organ 'slab_inclusion', got {tissue.organ!r}")
        tissue.volume_options = {**dict(tissue.volume_options),
                                 "inclusion_centre": (float(o.inclusion_xy[0]), float(o.inclusion_xy[1]), -0.002)}
    for tool in cfg.tools:
        if o.mu is not None:
            tool.friction = float(o.mu)
    cfg.seed = int(sc.meta.seed)
    return cfg


def build_simulation(sc: Scenario):
    """Build the scenario's :class:`~surgsim_envs.scene.Simulation`."""
    from surgsim_envs.scene import Simulation, make_scene

    cfg = scene_config(sc)
    return Simulation(make_scene(sc.meta.scene, cfg))


def inclusion_centre(sim) -> np.ndarray | None:
    """(3,) m centre of the stiff inclusion (nodes labelled 1), or None when there is none."""
    vol = getattr(sim.tissue(), "volume", None)
    if vol is None or not hasattr(vol, "node_labels"):
        return None
    mask = np.asarray(vol.node_labels) == 1
    if not mask.any():
        return None
    return np.asarray(vol.nodes)[mask].mean(axis=0)


# ----------------------------------------------------------------------------------------------
# Drivers
class PlanDevice:
    """Factory of the default simulated hand for ``device = "scripted"`` without a script file:
    a :class:`~surgsim_envs.haptics.HapticDevice` whose pose follows the phase plan plus a seeded
    physiological tremor (``tremor`` m, 8-12 Hz)."""

    @staticmethod
    def make(runner: "_Runner", tremor: float, seed: int):
        from surgsim_envs.haptics.device import DeviceState, HapticDevice

        rng = np.random.default_rng(seed)
        freq = rng.uniform(8.0, 12.0, size=3)
        phase0 = rng.uniform(0.0, 2 * math.pi, size=3)

        class _PlanHand(HapticDevice):
            name = "scripted-plan"

            def _read(self, t):
                offset, radius = runner.plan_command()
                pos = offset + tremor * np.sin(2 * math.pi * freq * t + phase0)
                return DeviceState(time=t, position=pos, grip=runner.grip_of(radius))

        return _PlanHand()


def make_device(spec: str, script: str, runner: "_Runner", tremor: float, seed: int):
    """A connected-to-be HapticDevice from a spec: scripted | replay:FILE | keyboard | udp:PORT
    (:func:`surgsim_envs.haptics.device_kinds.make_device`; "scripted" is the scenario's phase plan, or
    ``script``; a replay FILE is resolved in the scenario's folder)."""
    from surgsim_envs.haptics.device import DeviceLimits
    from surgsim_envs.haptics.device_kinds import make_device as make
    from surgsim_envs.scenarios.schema import resolve_data_file

    limits = DeviceLimits(max_force=1e6)  # the scenario scores forces; the device only records them
    def scripted():
        if script:
            from surgsim_envs.haptics.scripted import ScriptedDevice, TrajectorySpec
            from surgsim_envs.haptics.teleop import load_script

            path = str(resolve_data_file(script, runner.sc.folder))
            return ScriptedDevice(TrajectorySpec.from_dict(load_script(path)), limits=limits)
        dev = PlanDevice.make(runner, tremor, seed)
        dev.limits = limits
        return dev

    return make(spec, limits=limits, scripted=scripted, base_dir=runner.sc.folder)


# ----------------------------------------------------------------------------------------------
class _Runner:
    """Steps one run of a phase scenario."""

    def __init__(self, sc: Scenario, sim, scale: float, bar=None, renderer=None, writer=None, viewer=None,
                 camera: str = "overview", tremor: float = 0.0):
        self.sc, self.sim, self.scale = sc, sim, scale
        self.bar, self.renderer, self.writer, self.viewer, self.camera = bar, renderer, writer, viewer, camera
        self._wall0 = None   # wall clock at sim time 0 (viewer pacing)
        self.ctx = PhaseContext(sim, SCENE_TOOL[sc.meta.scene], scale=scale)
        self.rec = Recording()
        self.tremor = tremor
        self._devices: dict[str, Any] = {}
        self._policies: dict[str, Callable] = {}
        self._phase = None
        self._s = 0.0

    # -- helpers for devices and policies -----------------------------------------------------
    def plan_command(self):
        return self._phase.command(self.ctx, self._s)

    def grip_of(self, radius) -> float:
        if not self.ctx.has_jaws:
            return 0.0
        cfg = self.ctx.tool.config
        r = self.ctx.radius if radius is None else radius
        return float((cfg.open_radius - r) / (cfg.open_radius - cfg.min_radius))

    def _radius_of(self, grip: float):
        if not self.ctx.has_jaws or not math.isfinite(grip):
            return None
        cfg = self.ctx.tool.config
        return cfg.open_radius - float(np.clip(grip, 0.0, 1.0)) * (cfg.open_radius - cfg.min_radius)

    def _device(self, phase):
        key = phase.device
        if key not in self._devices:
            dev = make_device(key, self.sc.trainee.script, self, self.tremor, self.sc.meta.seed)
            dev.connect()
            self._devices[key] = dev
        return self._devices[key]

    def _policy(self, phase):
        if phase.policy not in self._policies:
            self._policies[phase.policy] = policy_for(self.sc, phase.policy)
        return self._policies[phase.policy]

    def _observation(self, i, t_phase) -> dict:
        sim, ctx = self.sim, self.ctx
        rep = sim.contact_report()[ctx.tool.name]
        return {"time": sim.time, "phase": self.sc.phases[i].type, "phase_index": i, "phase_time": t_phase,
                "phase_fraction": self._s, "offset": ctx.offset.copy(), "opening": ctx.radius,
                "tool_position": sim.tool_position(ctx.tool.name), "normal_force": rep["normal_force"],
                "tangential_force": rep["tangential_force"], "pull_force": ctx.pull_force(),
                "surface_z": ctx.surface_z, "home": ctx.home.copy()}

    # -- main loop ----------------------------------------------------------------------------
    def _sample(self, i) -> None:
        sim, ctx = self.sim, self.ctx
        rep = sim.contact_report()[ctx.tool.name]
        opening = sim.jaw_opening(ctx.tool.name) if ctx.has_jaws else math.nan
        self.rec.add(sim.time, i, rep["normal_force"], rep["tangential_force"], ctx.pull_force(), rep["slipping"],
                     rep["contacts"], rep["penetration"], sim.tool_position(ctx.tool.name), opening)

    def run(self) -> tuple[bool, str | None]:
        sim, ctx, sc = self.sim, self.ctx, self.sc
        period = sc.meta.sample_period
        next_sample = 0.0
        next_frame = 0.0
        steps_frame = max(1, int(round(1.0 / FPS / sim.dt)))
        for i, phase in enumerate(sc.phases):
            phase.check(ctx)
        try:
            for i, phase in enumerate(sc.phases):
                duration = phase.duration * self.scale
                n = max(1, int(round(duration / sim.dt)))
                start = sim.time
                self.rec.phase_names.append(phase.label or phase.type)
                self._phase = phase
                self._s = 0.0
                phase.begin(ctx)
                next_policy = 0.0
                for k in range(n):
                    self._s = (k + 1) / n
                    if phase.driver == "script":
                        offset, radius = phase.command(ctx, self._s)
                    elif phase.driver == "device":
                        dev = self._device(phase)
                        state = dev.read(sim.time)
                        offset, radius = np.asarray(state.position, dtype=float), self._radius_of(state.grip)
                        dev.send_force(-sim.tool_force(ctx.tool.name), sim.time)
                    else:
                        if k * sim.dt >= next_policy - 1e-12:
                            act = self._policy(phase)(self._observation(i, k * sim.dt))
                            next_policy += CONTROL_PERIOD
                            self._act = _parse_policy_action(act, phase.policy)
                        offset, radius = self._act.get("offset", ctx.offset), self._act.get("opening")
                    ctx.apply(offset, radius)
                    sim.physics_step()
                    if sim.time >= next_sample - 1e-12:
                        self._sample(i)
                        next_sample += period
                    if (k + 1) % steps_frame == 0:
                        self._frame(next_frame)
                        if self.bar is not None:
                            self.bar.update(steps_frame * sim.dt)
                self.rec.phase_spans.append({"index": i, "type": phase.type, "label": phase.label or phase.type,
                                             "driver": phase.driver, "start": start, "end": sim.time})
            return True, None
        except TissueUnstableError as exc:
            self.rec.phase_spans.append({"index": len(self.rec.phase_spans), "type": self._phase.type,
                                         "label": self._phase.label or self._phase.type,
                                         "driver": self._phase.driver, "start": start, "end": sim.time})
            return False, str(exc)
        finally:
            for dev in self._devices.values():
                dev.close()

    def _frame(self, _t) -> None:
        if self.writer is not None:
            self.writer.write(self.renderer.render(self.camera))
        if self.viewer is not None:  # pragma: no cover - needs a display
            if not self.viewer.is_running():
                raise KeyboardInterrupt("viewer closed")
            self.sim.sync_visual()
            self.viewer.sync()
            # Play at real time (a trainee watches the scenario at the speed it happens), never
            # faster: a 1 s scenario used to flash past in a fraction of a second.
            if self._wall0 is None:
                self._wall0 = time.perf_counter() - self.sim.time
            ahead = self.sim.time - (time.perf_counter() - self._wall0)
            if ahead > 0.0:
                time.sleep(ahead)
            elif ahead < -0.1:                  # slower than real time: no rush to catch up later
                self._wall0 = time.perf_counter() - self.sim.time


def _parse_policy_action(act, ref: str) -> dict:
    if isinstance(act, dict):
        out = {}
        if "offset" in act:
            off = np.asarray(act["offset"], dtype=float).reshape(-1)
            if off.shape != (3,) or not np.all(np.isfinite(off)):
                raise ConfigError(f"policy {ref!r} returned offset {act['offset']!r}; give 3 finite numbers (m)")
            out["offset"] = off
        if act.get("opening") is not None:
            out["opening"] = float(act["opening"])
        return out
    off = np.asarray(act, dtype=float).reshape(-1)
    if off.shape != (3,):
        raise ConfigError(f"policy {ref!r} returned {act!r}; return {{'offset': [x, y, z], 'opening': m}}")
    return {"offset": off}


# ----------------------------------------------------------------------------------------------
def _evaluate(sc: Scenario, values: dict, rec: Recording, completed: bool, error, sim, wall: float,
              info: dict | None = None) -> RunResult:
    from surgsim_envs.scenarios.scoring import compute_metrics, default_criteria, safety_violations, score_criteria

    truth = surface = None
    tip = 0.0
    if sim is not None and sc.meta.scene == "palpation":
        truth = inclusion_centre(sim)
        tool = sim.tool(SCENE_TOOL["palpation"])
        tip = float(tool.config.tip_radius)
        surface = float(sim.tissue().volume.nodes[:, 2].max()) if hasattr(sim.tissue(), "volume") else None
    limit = sc.scoring.safety_limit
    metrics = compute_metrics(rec, limit, completed, truth, surface, tip)
    criteria = sc.scoring.criteria or default_criteria(limit, truth is not None)
    score, results = score_criteria(metrics, criteria)
    violations = safety_violations(rec.t, rec.normal, limit)
    return RunResult(sc, values, rec, completed, error, metrics, score, results, violations, wall, info or {})


def run_one(sc: Scenario, values: dict | None = None, *, video_path=None, viewer: bool = False, bar=None,
            camera: str = "overview", tremor: float = 0.0) -> RunResult:
    """Run one (non-sweep) phase scenario; ``video_path`` writes an MP4 (skipped without OpenGL)."""
    wall0 = time.perf_counter()
    sim = build_simulation(sc)
    renderer = writer = view = None
    if video_path is not None:
        from surgsim_envs.scene.render import SceneRenderer, VideoWriter

        try:
            renderer = SceneRenderer(sim, 640, 480)
            if camera not in renderer.cameras:
                camera = renderer.cameras[0] if renderer.cameras else -1
            writer = VideoWriter(video_path, FPS, (640, 480))
        except RenderingUnavailableError as exc:
            print(f"surgsim run: no video: {exc}")
            renderer = writer = None
    if viewer:  # pragma: no cover - needs a display
        from surgsim_envs.scene.display import open_viewer, require_display

        require_display("surgsim run --viewer")   # raises; MuJoCo would exit the process
        view = open_viewer(sim.render_model, sim.sync_visual())   # MuJoCo's side panels hidden
        from surgsim_envs.scene.display import frame_tissue

        frame_tissue(view, sim)   # free camera on the tissue (the default frames the whole floor)
    try:
        runner = _Runner(sc, sim, sc.meta.duration_scale, bar, renderer, writer, view, camera, tremor)
        completed, error = runner.run()
    finally:
        if writer is not None:
            writer.close()
        if renderer is not None:
            renderer.close()
        if view is not None:  # pragma: no cover
            from surgsim_envs.scene.display import close_viewer

            close_viewer(view)  # waits for the window thread (exiting under it segfaults)
    rec = runner.rec.finish()
    info = {"video": str(video_path) if writer is not None else None, "dt": sim.dt,
            "tissue_nodes": int(sim.tissue().n_nodes), "tissue_model": sim.tissue().name}
    return _evaluate(sc, values or {}, rec, completed, error, sim, time.perf_counter() - wall0, info)


def apply_overrides(sc: Scenario, duration_scale: float = 1.0, device: str | None = None,
                    policy: str | None = None) -> Scenario:
    """Copy of ``sc`` with the CLI's overrides: a duration scale, every phase driven by ``device``
    or by ``policy`` (for task rollouts ``policy`` replaces ``[policy] file``)."""
    from surgsim_envs.scenarios.schema import KeyLocator, ValidationContext, validate_driver

    out = sc.scaled(duration_scale) if duration_scale != 1.0 else copy.deepcopy(sc)
    ctx = ValidationContext("command line", KeyLocator(None))
    if device is not None:
        validate_driver(ctx, ("--device",), "device", device, "")
        for ph in out.phases:
            ph.driver, ph.device = "device", device
        out.trainee.driver, out.trainee.device = "device", device
    if policy is not None:
        out.trusted_policy = policy  # typed by the user, not read from the shared file
        if out.policy is not None:
            out.policy.file = policy
        else:
            for ph in out.phases:
                ph.driver, ph.policy = "policy", policy
            out.trainee.driver, out.trainee.policy = "policy", policy
    return out


def run_scenario(sc: Scenario, *, duration_scale: float = 1.0, device: str | None = None, policy: str | None = None,
                 out_dir=None, video: bool = False, viewer: bool = False, progress: bool = True,
                 tremor: float = 0.0) -> list[RunResult]:
    """Run every run of ``sc`` (one per sweep value) and return their results.

    out_dir: where videos go (``video.mp4`` or ``video_<run>.mp4``); reports are written by
    :func:`surgsim_envs.scenarios.report.write_report`.
    """
    sc = apply_overrides(sc, duration_scale, device, policy)
    if sc.meta.task:
        from surgsim_envs.scenarios.rollout import run_rollout

        return [run_rollout(sc, progress=progress)]
    runs = sc.runs()
    total = sum(p.duration for p in sc.phases) * sc.meta.duration_scale * len(runs)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=round(total, 6), mininterval=0.5, unit="sim s",
                   bar_format="{l_bar}{bar}| {n:.2f}/{total:.2f} sim s [{elapsed}]")
    results = []
    try:
        for k, (values, run_sc) in enumerate(runs):
            video_path = None
            if video and out_dir is not None:
                tag = "" if not values else "_" + "_".join(f"{a}{b}" for a, b in values.items())
                video_path = Path(out_dir) / f"video{tag}.mp4"
            if bar is not None:
                bar.set_description(sc.name + ("" if not values else " " + ", ".join(f"{a}={b}" for a, b in values.items())))
            results.append(run_one(run_sc, values, video_path=video_path, viewer=viewer, bar=bar,
                                   tremor=tremor or sc.trainee.tremor))
    finally:
        if bar is not None:
            bar.close()
    return results
