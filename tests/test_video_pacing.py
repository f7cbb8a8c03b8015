"""Teleop recordings: videos run at their nominal frame rate (slow rendering duplicates
frames instead of fast-forwarding the video); malformed force logs name the line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.haptics.recording import PacedVideoWriter


class _Sink:
    def __init__(self):
        self.frames, self.released = [], False

    def write(self, image):
        self.frames.append(image)

    def release(self):
        self.released = True


class _Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


@pytest.mark.parametrize("render_s", [0.375, 0.125, 0.046875, 0.0078125])  # exact binary fractions
def test_video_has_fps_times_duration_frames_whatever_the_render_time(render_s):
    fps, duration = 32.0, 3.0
    sink, clock = _Sink(), _Clock()
    w = PacedVideoWriter(sink, fps, clock=clock)
    t0, k = clock.t, 0
    while clock.t - t0 < duration:
        w.write(k)  # the image rendered now (its id is the render index)
        k += 1
        clock.t += render_s
    w.close(duration)
    assert sink.released and len(sink.frames) == round(fps * duration)
    # frame j shows the newest image rendered at or before j / fps
    render_times = np.arange(k) * render_s
    for j, img in enumerate(sink.frames):
        newest = int(np.searchsorted(render_times, j / fps, side="right")) - 1
        assert img == min(newest, k - 1)
    assert w.images_rendered == k


def test_renders_faster_than_the_frame_rate_are_not_all_written():
    sink, clock = _Sink(), _Clock()
    w = PacedVideoWriter(sink, 8.0, clock=clock)
    for i in range(64):  # 64 renders in 1 s at 8 frames/s
        w.write(i)
        clock.t += 1 / 64
    w.close(1.0)
    assert sink.frames == [0, 8, 16, 24, 32, 40, 48, 56]


def test_bad_fps_is_a_config_error():
    with pytest.raises(ConfigError, match="fps"):
        PacedVideoWriter(_Sink(), 0.0)


def test_teleop_headless_video_lasts_as_long_as_the_run(tmp_path, capsys):
    cv2 = pytest.importorskip("cv2")
    pytest.importorskip("surgsim_envs.haptics.scene_adapter", exc_type=ImportError)
    from surgsim_envs.cli import main

    out = tmp_path / "tele"
    rc = main(["teleop", "palpation", "--device", "scripted", "--headless", "--out", str(out), "--duration", "1.0",
               "--fps", "20", "--size", "160", "120"])
    text = capsys.readouterr()
    if rc != 0 and "rendering" in text.err:
        pytest.skip(f"no offscreen rendering here: {text.err.strip()}")
    assert rc == 0, text.err
    cap = cv2.VideoCapture(str(out / "teleop_palpation.mp4"))
    frames = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    fps = cap.get(cv2.CAP_PROP_FPS)
    cap.release()
    assert fps == pytest.approx(20.0)
    wall = json.loads((out / "stats.json").read_text())["duration_s"]  # >= 1 s: the first render is slow
    assert wall >= 1.0 and frames == round(wall * fps)  # plays in real time, however few images were rendered


@pytest.mark.parametrize("row, message", [("0.1,1,x,3,0", "line 3: not four numbers"),
                                          ("0.1,1,nan,3,0", "line 3: non-finite"), ("0.1,1,2", "line 3: not four")])
def test_malformed_force_log_rows_name_the_line(tmp_path, row, message):
    from surgsim_envs.haptics.recording import ForceLog

    f = tmp_path / "log.csv"
    f.write_text("t,fx,fy,fz,saturated\n0.0,0,0,0,0\n" + row + "\n")
    with pytest.raises(ConfigError, match=message):
        ForceLog.from_csv(f)
