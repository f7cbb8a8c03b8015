"""Haptics: devices, servo loop, force extrapolation and safety, against an analytic spring wall.

No wall-clock timing is asserted: the servo runs on its simulated clock here (the threaded
loop's timing is measured by ``surgsim bench haptics``).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.haptics import (
    DeviceLimits,
    DeviceState,
    ForceLog,
    HapticDevice,
    KeyboardDevice,
    LinearExtrapolator,
    ReplayDevice,
    ScriptedDevice,
    ServoConfig,
    ServoLoop,
    SpringWallPhysics,
    StiffnessExtrapolator,
    TrajectorySpec,
    linear_step_bound,
    press_spec,
    save_poses,
)
from surgsim_envs.haptics import keyboard as kb

H = 1e-3  # servo period, s


class RecordingWall(SpringWallPhysics):
    """The spring wall, logging its state after every physics update read by the servo."""

    def __init__(self, **kw):
        super().__init__(**kw)
        self.log = []

    def coupling_force(self):
        f = super().coupling_force()
        self.log.append((self.time, f[2], self.contact_force()[2], self.proxy[2], self.v[2]))
        return f


def run_press(physics_rate=None, extrapolation="linear", profile="linear", speed=0.01, depth=0.005, **wall):
    dev = ScriptedDevice(press_spec(depth=depth, approach=0.005, speed=speed, dwell=0.3, profile=profile),
                         limits=DeviceLimits(max_force=10.0))
    phys = RecordingWall(start_position=(0, 0, 0.005), **wall)
    with dev:
        loop = ServoLoop(dev, phys, ServoConfig(extrapolation=extrapolation))
        stats = loop.run_simulated(dev.duration + 0.05, physics_rate_hz=physics_rate)
    return dev, phys, stats


# --- servo + coupling -------------------------------------------------------------------------
def test_press_force_grows_with_depth_and_matches_contact_force():
    speed, depth = 0.01, 0.005
    dev, phys, stats = run_press(speed=speed, depth=depth)
    felt = dev.force_log.forces[:, 2]
    t_log, f_hand, f_contact, proxy_z, v_tool = map(np.array, zip(*phys.log))
    assert len(felt) == len(f_hand) == stats.ticks
    # what the device received is the physics' hand force (physics updated every tick)
    np.testing.assert_allclose(felt, f_hand, atol=1e-12)
    assert stats.rejected_poses == 0 and stats.saturated == 0 and stats.rate_limited == 0

    # press-in phase: proxy below the wall and still descending
    descending = np.r_[False, np.diff(proxy_z) < -1e-9]
    onset = np.argmax((proxy_z < 0) & descending)
    press = np.where(descending & (proxy_z < 0))[0]
    press = press[press > onset + 30]  # 30 ms after contact onset: coupling transient decayed
    assert len(press) > 300
    # force grows with depth
    assert np.all(np.diff(felt[press]) > 0)
    assert np.corrcoef(-proxy_z[press], felt[press])[0, 1] > 0.999
    # matches the contact force within the coupling's documented error c*v (quasi-static)
    err = np.abs(felt[press] - f_contact[press])
    assert np.all(err <= phys.damping * speed)
    assert err.max() > 0  # the drag term is real: the check is not vacuous

    # at rest at the bottom: equal to the contact force and to the series-spring law
    bottom = np.where(np.abs(proxy_z + depth) < 1e-12)[0]
    last = bottom[-1]
    assert abs(felt[last] - f_contact[last]) < 1e-4
    assert felt[last] == pytest.approx(phys.series_stiffness * depth, rel=1e-3)
    # in free space (above the wall, at rest) nothing is felt
    assert abs(felt[0]) < 1e-12


def test_extrapolation_250hz_tracks_1khz_reference_with_bounded_steps():
    ref_dev, _, _ = run_press(physics_rate=None, profile="minimum_jerk", speed=0.02, depth=0.006)
    ref = ref_dev.force_log.forces[:, 2]
    f_rate = np.max(np.abs(np.diff(ref))) / H  # N/s
    f_accel = np.max(np.abs(np.diff(ref, 2))) / H**2  # N/s^2
    bound = linear_step_bound(f_rate, f_accel, H, 4 * H)

    out = {}
    for method in ("hold", "linear", "stiffness"):
        dev, phys, stats = run_press(physics_rate=250, extrapolation=method, profile="minimum_jerk", speed=0.02, depth=0.006)
        assert stats.physics_updates == pytest.approx(stats.ticks / 4, abs=1)
        assert stats.rate_limited == 0  # the bound below is the extrapolator's, not the safety clamp's
        f = dev.force_log.forces[:, 2]
        out[method] = (np.sqrt(np.mean((f - ref) ** 2)), np.max(np.abs(np.diff(f))))

    rms_hold, _ = out["hold"]
    rms_lin, step_lin = out["linear"]
    rms_stiff, step_stiff = out["stiffness"]
    assert step_lin <= bound
    assert step_stiff <= bound
    peak = np.max(np.abs(ref))
    assert rms_lin < 0.005 * peak and rms_stiff < 0.005 * peak
    assert rms_lin < 0.3 * rms_hold and rms_stiff < 0.3 * rms_hold  # extrapolation beats zero-order hold


def test_linear_extrapolator_is_exact_on_ramp_and_freezes_after_one_interval():
    ex = LinearExtrapolator()
    x = np.zeros(3)
    ex.update(0.000, [0, 0, 1.0], x)
    ex.update(0.004, [0, 0, 1.4], x)  # 100 N/s
    assert ex.force(0.006, x)[2] == pytest.approx(1.6)
    assert ex.force(0.008, x)[2] == pytest.approx(1.8)
    assert ex.force(0.100, x)[2] == pytest.approx(1.8)  # physics stalled: horizon capped at T
    assert np.all(np.isfinite(ex.force(0.1, x)))
    ex.update(0.012, [np.nan, 0, 0], x)  # a non-finite sample is ignored
    assert ex.force(0.006, x)[2] == pytest.approx(1.6)


def test_stiffness_extrapolator_reproduces_linear_wall_and_never_pulls():
    k = 400.0
    ex = StiffnessExtrapolator()
    ex.update(0.0, [0, 0, k * 0.001], [0, 0, -0.001])
    ex.update(0.004, [0, 0, k * 0.002], [0, 0, -0.002])  # estimated k from the samples
    assert ex.k == pytest.approx(k)
    assert ex.force(0.005, [0, 0, -0.0025])[2] == pytest.approx(k * 0.0025)
    assert ex.force(0.005, [0.003, 0, -0.0025])[0] == 0.0  # tangential motion: no spurious force
    assert ex.force(0.005, [0, 0, 0.05])[2] == 0.0  # pulled out: normal force clipped at zero


# --- safety -------------------------------------------------------------------------------------
def test_forces_above_device_max_are_clamped():
    dev = ScriptedDevice(press_spec(depth=0.01, approach=0.002, speed=0.02, dwell=0.1), limits=DeviceLimits(max_force=1.5))
    with dev:
        loop = ServoLoop(dev, SpringWallPhysics(start_position=(0, 0, 0.002)), ServoConfig(max_force_rate=1e5))
        stats = loop.run_simulated(dev.duration)
        direct = dev.send_force([30.0, 40.0, 0.0], 99.0)
        nan = dev.send_force([np.nan, 0, 0], 99.001)
    mags = dev.force_log.magnitudes
    assert stats.saturated > 0
    assert np.max(mags) <= 1.5 + 1e-12
    assert np.max(mags) == pytest.approx(1.5)  # the wall asked for more (400 N/m * 1 cm = 4 N)
    np.testing.assert_allclose(direct, [0.9, 1.2, 0.0])  # direction kept
    np.testing.assert_array_equal(nan, np.zeros(3))
    assert dev.force_log.saturated[-1] and dev.force_log.saturated[-2]


class ConstantForcePhysics:
    dt = 1e-3

    def __init__(self, force):
        self.time, self.force = 0.0, np.asarray(force, float)

    def set_proxy_pose(self, p, q):
        self.p = np.asarray(p)

    def step(self):
        self.time += self.dt

    def coupling_force(self):
        return self.force


class StillDevice(HapticDevice):
    name = "still"

    def __init__(self, nan_ticks=(), **kw):
        super().__init__(**kw)
        self.nan_ticks = set(nan_ticks)
        self.calls = 0

    def _read(self, t):
        i = self.calls
        self.calls += 1
        pos = np.array([np.nan, 0, 0]) if i in self.nan_ticks else np.array([0.0, 0.0, 0.001 * i])
        return DeviceState(time=t, position=pos)


def test_force_rate_clamp_limits_every_step():
    dev = StillDevice(limits=DeviceLimits(max_force=10))
    with dev:
        loop = ServoLoop(dev, ConstantForcePhysics([0, 0, 3.0]), ServoConfig(max_force_rate=500.0))
        stats = loop.run_simulated(0.02)
    f = dev.force_log.forces[:, 2]
    assert np.max(np.abs(np.diff(np.r_[0.0, f]))) <= 0.5 + 1e-12
    assert f[-1] == pytest.approx(3.0)
    np.testing.assert_allclose(f[:6], [0.5, 1.0, 1.5, 2.0, 2.5, 3.0])  # a ramp at 500 N/s, not a 3 N step
    assert stats.rate_limited == 5


def test_nan_poses_are_rejected_and_last_good_pose_is_kept():
    nan_ticks = {0, 5, 6, 7, 20}
    dev = StillDevice(nan_ticks=nan_ticks, limits=DeviceLimits(max_force=10))
    phys = SpringWallPhysics(start_position=(0, 0, 0.0))
    with dev:
        loop = ServoLoop(dev, phys)
        stats = loop.run_simulated(0.03)
        assert stats.rejected_poses == len(nan_ticks)
        assert np.all(np.isfinite(loop.proxy_target))
    assert np.all(np.isfinite(dev.force_log.forces))
    assert np.all(np.isfinite(phys.x)) and np.all(np.isfinite(phys.proxy))
    assert dev.force_log.forces[0].tolist() == [0.0, 0.0, 0.0]  # no pose yet: zero force


def test_workspace_is_enforced():
    dev = ScriptedDevice({"waypoints": [[0, 0, 0], [0.5, 0, 0]], "speeds": 1.0}, limits=DeviceLimits())
    phys = SpringWallPhysics(start_position=(0, 0, 0.02), wall_z=-1.0)
    with dev:
        loop = ServoLoop(dev, phys)
        stats = loop.run_simulated(0.6)
    assert stats.workspace_clamped > 0
    assert loop.proxy_target[0] == pytest.approx(DeviceLimits().workspace_max[0])


def test_bad_config_is_rejected_with_a_clear_message():
    with pytest.raises(ConfigError, match="rate_hz"):
        ServoConfig(rate_hz=0)
    with pytest.raises(ConfigError, match="extrapolation"):
        ServoConfig(extrapolation="cubic")
    with pytest.raises(ConfigError, match="max_force"):
        DeviceLimits(max_force=-1)
    with pytest.raises(ConfigError, match="not a haptic physics"):
        ServoLoop(StillDevice(), object())
    with pytest.raises(ConfigError, match="not connected"):
        StillDevice().read(0.0)


# --- scripted device ----------------------------------------------------------------------------
def tremor_spec(seed):
    return TrajectorySpec(waypoints=[[0, 0, 0.01]], dwell=2.0, tremor_amplitude=3e-4, drift_speed=1e-3, seed=seed)


def test_scripted_device_is_reproducible_with_a_seed():
    t = np.arange(0, 2.0, H)
    def sample(seed, order=1):
        with ScriptedDevice(tremor_spec(seed)) as dev:
            return np.array([dev.read(ti).position for ti in t[::order]])[::order]
    a, b, c = sample(3), sample(3, order=-1), sample(4)
    np.testing.assert_array_equal(a, b)  # bit for bit, whatever the read order
    assert not np.array_equal(a, c)


def test_scripted_tremor_is_physiological_and_drift_is_linear():
    spec = tremor_spec(7)
    dev = ScriptedDevice(spec).connect()
    t = np.arange(0, 2.0, H)
    pos = np.array([dev.read(ti).position for ti in t])
    drift = spec.drift_speed * t[:, None] * dev._drift_dir
    tremor = pos - np.array([0, 0, 0.01]) - drift
    assert np.max(np.abs(tremor)) <= spec.tremor_amplitude + 1e-15
    freqs = np.fft.rfftfreq(len(t), H)
    for axis in range(3):
        spectrum = np.abs(np.fft.rfft(tremor[:, axis]))
        assert 8.0 <= freqs[np.argmax(spectrum)] <= 12.0
    moved = np.linalg.norm(pos[-1] - pos[0] - (tremor[-1] - tremor[0]))
    assert moved == pytest.approx(spec.drift_speed * t[-1], rel=1e-9)
    dev.close()


def test_scripted_waypoints_speed_and_dwell():
    spec = TrajectorySpec(waypoints=[[0, 0, 0], [0.01, 0, 0], [0.01, 0.02, 0]], speeds=[0.01, 0.02],
                          dwell=[0.1, 0.2, 0.0], grip=[0, 1, 1])
    assert spec.duration == pytest.approx(0.1 + 1.0 + 0.2 + 1.0)
    with ScriptedDevice(spec) as dev:
        assert dev.read(0.05).position.tolist() == [0, 0, 0]
        s = dev.read(0.6)
        np.testing.assert_allclose(s.position, [0.005, 0, 0], atol=1e-15)
        assert s.grip == pytest.approx(0.5)
        np.testing.assert_allclose(dev.read(1.8).position, [0.01, 0.01, 0], atol=1e-15)
        np.testing.assert_allclose(dev.read(10.0).position, [0.01, 0.02, 0])
    with pytest.raises(ConfigError, match="speeds"):
        TrajectorySpec(waypoints=[[0, 0, 0], [1, 0, 0]], speeds=-1)
    with pytest.raises(ConfigError, match="tremor_frequency"):
        TrajectorySpec(waypoints=[[0, 0, 0]], tremor_frequency=(12, 8))
    with pytest.raises(ConfigError, match="unknown trajectory keys"):
        TrajectorySpec.from_dict({"waypoints": [[0, 0, 0]], "sped": 1})


# --- replay -------------------------------------------------------------------------------------
def _states():
    return [DeviceState(time=0.5 + 0.1 * i, position=np.array([0.001 * i, 0.0, -0.002 * i]),
                        quaternion=np.array([1.0, 0, 0, 0]), buttons=i % 2, grip=0.1 * i) for i in range(5)]


@pytest.mark.parametrize("suffix", [".csv", ".json"])
def test_replay_device_reads_csv_and_json(tmp_path, suffix):
    path = save_poses(tmp_path / f"hand{suffix}", _states())
    with ReplayDevice(path) as dev:
        assert dev.duration == pytest.approx(0.4)
        s0 = dev.read(0.0)  # first sample plays at servo time 0
        np.testing.assert_allclose(s0.position, [0, 0, 0])
        mid = dev.read(0.15)  # half-way between samples 1 and 2
        np.testing.assert_allclose(mid.position, [0.0015, 0, -0.003])
        assert mid.grip == pytest.approx(0.15) and mid.buttons == 1
        np.testing.assert_allclose(dev.read(5.0).position, [0.004, 0, -0.008])  # held after the end


def test_replay_reads_minimal_csv_and_rejects_bad_files(tmp_path):
    p = tmp_path / "min.csv"
    p.write_text("t,x,y,z\n0,0,0,0\n1,0.01,0,0\n")
    with ReplayDevice(p) as dev:
        assert dev.read(0.5).position[0] == pytest.approx(0.005)
        np.testing.assert_allclose(dev.read(0.5).quaternion, [1, 0, 0, 0])
    bad = tmp_path / "bad.csv"
    bad.write_text("t,x,y,z\n0,0,0,0\n0,0.01,0,0\n")
    with pytest.raises(ConfigError, match="increase"):
        ReplayDevice(bad)
    nocol = tmp_path / "nocol.csv"
    nocol.write_text("time,x\n0,0\n")
    with pytest.raises(ConfigError, match="t,x,y,z"):
        ReplayDevice(nocol)
    js = tmp_path / "v9.json"
    js.write_text(json.dumps({"version": 9, "samples": []}))
    with pytest.raises(ConfigError, match="version"):
        ReplayDevice(js)


# --- keyboard -----------------------------------------------------------------------------------
def test_keyboard_device_moves_with_synthetic_key_codes():
    dev = KeyboardDevice(step=0.002)
    with dev:
        for key in (kb.KEY_RIGHT, kb.KEY_RIGHT, kb.KEY_UP, kb.KEY_PAGE_DOWN, ord("q"), kb.KEY_J, kb.KEY_SPACE, 12345):
            dev.key_callback(key)
        s = dev.read(0.0)
        np.testing.assert_allclose(s.position, [0.004, 0.002, -0.004])
        assert s.grip == pytest.approx(0.1) and s.button(0)
        assert dev.keys_ignored == 1
        for _ in range(200):
            dev.key_callback(kb.KEY_LEFT)
        assert dev.read(0.0).position[0] == pytest.approx(DeviceLimits().workspace_min[0])
        dev.key_callback(kb.KEY_R)
        np.testing.assert_allclose(dev.read(0.0).position, [0, 0, 0])


# --- recording ----------------------------------------------------------------------------------
def test_force_log_round_trips_through_csv(tmp_path):
    log = ForceLog()
    log.append(0.0, [0, 0, 1.0])
    log.append(0.001, [0.5, 0, 1.5], saturated=True)
    back = ForceLog.from_csv(log.to_csv(tmp_path / "f.csv"))
    np.testing.assert_allclose(back.forces, log.forces)
    np.testing.assert_array_equal(back.saturated, [False, True])
    assert back.max_step() == pytest.approx(np.hypot(0.5, 0.5))


# --- the MuJoCo scene through the adapter -------------------------------------------------------
def test_scene_adapter_press_feels_the_tissue_contact_force():
    scene_adapter = pytest.importorskip("surgsim_envs.haptics.scene_adapter", exc_type=ImportError)
    from surgsim_envs.haptics import DeviceMapping

    phys = scene_adapter.make_haptic_simulation("palpation", spacing=0.00625, organ="slab")
    assert isinstance(phys, scene_adapter.SceneHapticPhysics)
    contact_z = scene_adapter.tissue_top(phys) + phys.tool.config.tip_radius
    gap = phys.home_position[2] - contact_z
    depths, felt, contact = [], [], []

    dev = ScriptedDevice(TrajectorySpec(waypoints=[[0, 0, 0], [0, 0, -gap - 0.003], [0, 0, -gap - 0.006]],
                                        speeds=0.02, dwell=[0.0, 0.4, 0.4], profile="minimum_jerk"),
                         limits=DeviceLimits(max_force=10.0))
    cfg = ServoConfig(mapping=DeviceMapping(origin=tuple(phys.home_position)))
    with dev:
        loop = ServoLoop(dev, phys, cfg)
        ends = dev.spec.segment_times()  # dwell0, move0, dwell1, move1, dwell2
        t = 0.0
        for stop in (ends[2], ends[4]):  # the ends of the two dwells: at rest at 3 mm and 6 mm
            while t < stop - 1e-9:
                t += H
                loop.tick(t, physics_until=t)
            felt.append(dev.force_log.forces[-1].copy())
            contact.append(phys.contact_force())
            depths.append(contact_z - phys.sim.tool_position("probe")[2])
    assert loop.stats.rejected_poses == 0
    # the proxy pulled the tool into the tissue; the hand is pushed back up, more when deeper
    assert 0 < depths[0] < depths[1]
    assert 0 < felt[0][2] < felt[1][2]
    # at rest the hand feels the tissue's contact force on the tool (the coupling carries it)
    for f, c in zip(felt, contact):
        np.testing.assert_allclose(f, c, atol=0.05 * abs(c[2]) + 1e-3)


# --- the teleop command -------------------------------------------------------------------------
def test_teleop_without_display_says_so_and_offers_headless(monkeypatch, capsys):
    from surgsim_envs.cli import main

    monkeypatch.delenv("DISPLAY", raising=False)
    assert main(["teleop", "palpation", "--device", "scripted"]) == 2
    err = capsys.readouterr().err
    assert "no display" in err and "--headless" in err
    assert main(["teleop", "grasp", "--device", "joystick", "--headless"]) == 2
    assert "scripted, replay:FILE, keyboard or udp:PORT" in capsys.readouterr().err
    assert main(["teleop", "grasp", "--device", "udp:notaport", "--headless"]) == 2


def test_keyboard_teleop_without_a_window_offers_only_commands_that_work(monkeypatch, capsys):
    """The keyboard reads keys from the viewer window: without a display (or with --headless) the
    advice is a virtual display or another device headless, never '--device keyboard --headless'."""
    from surgsim_envs.cli import main

    monkeypatch.delenv("DISPLAY", raising=False)
    for extra in ([], ["--headless"]):
        assert main(["teleop", "palpation", "--device", "keyboard", *extra]) == 2
        err = capsys.readouterr().err
        assert "reads its keys from the viewer window" in err
        assert "xvfb-run -a surgsim teleop palpation --device keyboard" in err
        assert "surgsim teleop palpation --device scripted --headless" in err
        assert "keyboard --headless" not in err and "drop --headless" not in err


def test_teleop_help_lists_the_key_bindings(capsys):
    from surgsim_envs.cli import main

    with pytest.raises(SystemExit):
        main(["teleop", "--help"])
    out = capsys.readouterr().out
    for keys, action in kb.KEY_BINDINGS:
        assert f"{keys}" in out and action in out
    assert "--panels" in out
    left, right = kb.key_overlay()
    assert len(left.splitlines()) == len(right.splitlines()) == len(kb.KEY_BINDINGS)


def test_teleop_headless_writes_video_and_force_log(tmp_path, capsys):
    pytest.importorskip("surgsim_envs.haptics.scene_adapter", exc_type=ImportError)
    from surgsim_envs.cli import main

    out = tmp_path / "tele"
    rc = main(["teleop", "palpation", "--device", "scripted", "--headless", "--out", str(out), "--duration", "0.6",
               "--fps", "10", "--size", "160", "120"])
    text = capsys.readouterr()
    if rc != 0 and "rendering" in text.err:
        pytest.skip(f"no offscreen rendering here: {text.err.strip()}")
    assert rc == 0, text.err
    assert "period median" in text.out
    log = ForceLog.from_csv(out / "force_log.csv")
    assert len(log) > 100 and np.all(np.isfinite(log.forces))
    stats = json.loads((out / "stats.json").read_text())
    assert stats["task"] == "palpation" and stats["ticks"] == pytest.approx(len(log), abs=2)
    assert (out / "teleop_palpation.mp4").stat().st_size > 0
    # H.264 wherever the [media] extra is installed (the test extra installs imageio-ffmpeg)
    pytest.importorskip("imageio_ffmpeg")
    import cv2

    cap = cv2.VideoCapture(str(out / "teleop_palpation.mp4"))
    fourcc = int(cap.get(cv2.CAP_PROP_FOURCC)).to_bytes(4, "little").decode("ascii", "replace").lower()
    assert fourcc == "h264" and int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) >= 5


def test_root_is_told_the_servo_takes_sched_fifo():
    from surgsim_envs.haptics.realtime import FIFO_PRIORITY, fifo_notice

    line = fifo_notice(True, euid=0)
    assert line is not None and "SCHED_FIFO" in line and f"priority {FIFO_PRIORITY}" in line
    assert "\n" not in line
    assert fifo_notice(True, euid=1000) is None and fifo_notice(False, euid=0) is None
