"""Videos people can open: H.264 where the installed codecs allow, a stated mp4v fallback."""

import numpy as np
import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.scene.media import VideoWriter, h264_available


def _fourcc(path):
    import cv2

    cap = cv2.VideoCapture(str(path))
    tag = int(cap.get(cv2.CAP_PROP_FOURCC)).to_bytes(4, "little").decode("ascii", "replace").lower()
    n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    return tag, n


def test_h264_when_available_else_stated_fallback(tmp_path):
    frames = [np.full((120, 160, 3), 10 * i, np.uint8) for i in range(12)]
    if h264_available():
        with VideoWriter(tmp_path / "a.mp4", 25, (160, 120)) as w:
            for f in frames:
                w.write(f)
        assert w.codec == "h264" and _fourcc(tmp_path / "a.mp4") == ("h264", 12)
    else:
        with pytest.warns(UserWarning, match="browsers and notebooks do not play"):
            w = VideoWriter(tmp_path / "a.mp4", 25, (160, 120))
        w.close()
    with VideoWriter(tmp_path / "b.mp4", 25, (160, 120), codec="mp4v") as w:
        for f in frames:
            w.write(f)
    tag, n = _fourcc(tmp_path / "b.mp4")
    assert w.codec == "mp4v" and tag in ("mp4v", "fmp4") and n == 12      # MPEG-4 part 2 (OpenCV reads "fmp4")
    with pytest.raises(ConfigError, match="codec='webm'"):
        VideoWriter(tmp_path / "c.mp4", 25, (160, 120), codec="webm")
    with pytest.raises(ConfigError, match=r"\(H, W, 3\) uint8 RGB"):
        VideoWriter(tmp_path / "d.mp4", 25, (160, 120), codec="mp4v").write(np.zeros((120, 160)))


def test_gymnasium_record_video_with_the_media_extra(tmp_path):
    pytest.importorskip("moviepy", reason="RecordVideo needs the [media] extra (moviepy)")
    import gymnasium as gym

    import surgsim_envs  # noqa: F401
    from surgsim_envs.errors import RenderingUnavailableError

    try:
        env = gym.make("SurgSim/Palpation-v0", render_mode="rgb_array", spacing=0.02, render_width=160,
                       render_height=160)
        env.reset(seed=0)
        env.render()
    except RenderingUnavailableError as exc:
        pytest.skip(f"no OpenGL: {exc}")
    env = gym.wrappers.RecordVideo(env, str(tmp_path), episode_trigger=lambda i: True, disable_logger=True)
    env.reset(seed=0)
    for _ in range(5):
        env.step(np.array([0, 0, -1, -1], dtype=np.float32))
    env.close()
    videos = list(tmp_path.glob("*.mp4"))
    assert videos and _fourcc(videos[0])[1] >= 5
