"""Video files people can open: H.264 MP4 where the installed codecs allow, a stated fallback else.

OpenCV's pip wheels carry no H.264 encoder (checked here: fourcc ``avc1``/``H264`` fail to open),
and their ``mp4v`` (MPEG-4 part 2) files do not play in browsers or notebooks. So
:class:`VideoWriter` encodes H.264 (libx264, yuv420p, ``+faststart``) through the ffmpeg binary
of ``imageio-ffmpeg`` when it is installed (the ``[media]`` extra, which also brings ``moviepy``
for ``gymnasium.wrappers.RecordVideo``), and otherwise falls back to OpenCV ``mp4v`` and says so
once (``VideoWriter.codec`` tells which one wrote the file). Every video the package writes goes
through it: ``surgsim demo``, ``surgsim run`` and ``surgsim teleop --headless``.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from surgsim_envs.errors import ConfigError, RenderingUnavailableError

#: what the fallback warning says
FALLBACK_NOTE = ("imageio-ffmpeg is not installed: writing MPEG-4 part 2 (mp4v), which browsers and notebooks do "
                 "not play; pip install 'surgsim_envs[media]' (imageio-ffmpeg) for H.264")
_warned = False


def h264_available() -> bool:
    """True if an H.264 encoder is installed (imageio-ffmpeg's ffmpeg with libx264)."""
    try:
        import imageio_ffmpeg

        imageio_ffmpeg.get_ffmpeg_exe()
    except Exception:
        return False
    return True


class VideoWriter:
    """Writes RGB frames (H, W, 3) uint8 to an MP4 file at ``fps`` frames per second.

    codec: "h264" (default if available), "mp4v" (OpenCV) or "auto" (h264, else mp4v with a
    warning). Frames of another size are resized to ``size`` = (width, height); odd sizes are
    rounded up to even for H.264 (yuv420p).
    """

    def __init__(self, path, fps: float, size: tuple[int, int], codec: str = "auto"):
        global _warned
        if not (isinstance(fps, (int, float)) and fps > 0):
            raise ConfigError(f"fps must be > 0, got {fps!r}")
        if codec not in ("auto", "h264", "mp4v"):
            raise ConfigError(f"codec={codec!r}; choose 'auto', 'h264' or 'mp4v'")
        self.path = Path(path).absolute()   # absolute: a relative path such as "-1/x.mp4" is not an ffmpeg option
        self.path.parent.mkdir(parents=True, exist_ok=True)
        w, h = int(size[0]), int(size[1])
        if codec == "h264" and not h264_available():
            raise RenderingUnavailableError(f"no H.264 encoder installed for {self.path}: {FALLBACK_NOTE}")
        self.codec = "h264" if codec in ("auto", "h264") and h264_available() else "mp4v"
        self.frames = 0
        if self.codec == "h264":
            import imageio_ffmpeg

            w, h = w + (w % 2), h + (h % 2)
            self._gen = imageio_ffmpeg.write_frames(str(self.path), (w, h), fps=float(fps), codec="libx264",
                                                    pix_fmt_in="rgb24", pix_fmt_out="yuv420p", macro_block_size=2,
                                                    output_params=["-movflags", "+faststart"], quality=7)
            self._gen.send(None)
            self._cv = None
        else:
            import cv2

            if codec == "auto" and not _warned:
                warnings.warn(FALLBACK_NOTE, stacklevel=2)
                _warned = True
            self._gen = None
            self._cv = cv2.VideoWriter(str(self.path), cv2.VideoWriter_fourcc(*"mp4v"), float(fps), (w, h))
            if not self._cv.isOpened():
                raise RenderingUnavailableError(f"OpenCV could not open {self.path} for MP4 (mp4v) writing")
        self.size = (w, h)

    def write(self, rgb: np.ndarray) -> None:
        """Append one RGB frame."""
        import cv2

        rgb = np.ascontiguousarray(rgb, dtype=np.uint8)
        if rgb.ndim != 3 or rgb.shape[2] != 3:
            raise ConfigError(f"a video frame must be (H, W, 3) uint8 RGB, got shape {rgb.shape}")
        if rgb.shape[:2] != (self.size[1], self.size[0]):
            rgb = cv2.resize(rgb, self.size)
        if self._gen is not None:
            self._gen.send(rgb)
        else:
            self._cv.write(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        self.frames += 1

    def close(self) -> None:
        if self._gen is not None:
            self._gen.close()
            self._gen = None
        if self._cv is not None:
            self._cv.release()
            self._cv = None

    def release(self) -> None:
        """:meth:`close` under OpenCV's name, so this writer is a frame sink wherever a
        ``cv2.VideoWriter`` was (e.g. haptics.recording.PacedVideoWriter)."""
        self.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
