"""The interactive paths as a person uses them, under a virtual display (Xvfb): the MuJoCo viewer
with render_mode="human", checked by a screenshot that shows the scene. Skips with a reason where
Xvfb / xdotool / xwd are absent (Debian: apt-get install xvfb xdotool x11-apps).

Not yet here: `surgsim teleop ... --device keyboard` driven by xdotool key events. Its viewer
window ("MuJoCo : palpation") opens under Xvfb, but at load ~15 the run did not finish within
240 s (not diagnosed; see the SCENE report of issue 18)."""

import os
import shutil
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

TOOLS = ("Xvfb", "xdotool", "xwd")


@pytest.fixture
def xvfb():
    missing = [t for t in TOOLS if shutil.which(t) is None]
    if missing:
        pytest.skip(f"virtual display tools missing: {missing} (apt-get install xvfb xdotool x11-apps)")
    for n in range(91, 120):
        if not os.path.exists(f"/tmp/.X11-unix/X{n}") and not os.path.exists(f"/tmp/.X{n}-lock"):
            break
    display = f":{n}"
    proc = subprocess.Popen(["Xvfb", display, "-screen", "0", "800x600x24", "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    for _ in range(100):
        if os.path.exists(f"/tmp/.X11-unix/X{n}"):
            break
        time.sleep(0.05)
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "WAYLAND_DISPLAY")}
    env["DISPLAY"] = display
    try:
        yield env
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def screenshot(env) -> np.ndarray:
    """(H, W, 3) uint8 RGB of the whole virtual screen (xwd, 24/32-bit TrueColor)."""
    raw = subprocess.run(["xwd", "-root", "-silent"], env=env, capture_output=True, check=True, timeout=30).stdout
    h = np.frombuffer(raw[:100], dtype=">u4")
    header, bpp, bpl, width, height, ncolors = int(h[0]), int(h[11]), int(h[12]), int(h[4]), int(h[5]), int(h[19])
    assert bpp in (24, 32), f"expected a 24- or 32-bit TrueColor screen, got {bpp} bits per pixel"
    nb = bpp // 8
    start = header + 12 * ncolors
    px = np.frombuffer(raw[start:start + bpl * height], dtype=np.uint8).reshape(height, bpl)[:, :width * nb]
    px = px.reshape(height, width, nb)
    little = int(h[7]) == 0                     # byte_order LSBFirst: B, G, R(, X)
    return px[..., [2, 1, 0]] if little else px[..., [nb - 3, nb - 2, nb - 1]]


def _wait_for(proc, word: str, timeout: float = 240.0) -> str:
    seen = ""
    t0 = time.time()
    while time.time() - t0 < timeout:
        line = proc.stdout.readline()
        if not line:
            if proc.poll() is not None:
                break
            continue
        seen += line
        if word in line:
            return seen
    raise AssertionError(f"child never printed {word!r}; output:\n{seen}\n{proc.stderr.read() if proc.stderr else ''}")


def test_human_viewer_shows_the_scene(xvfb):
    code = textwrap.dedent("""
        import time, numpy as np, gymnasium as gym, surgsim_envs
        env = gym.make("SurgSim/Palpation-v0", render_mode="human", spacing=0.02)
        env.reset(seed=0)
        for _ in range(20):
            env.step(np.array([0, 0, 1, -1], dtype=np.float32))
        time.sleep(1.0)
        print("READY", flush=True)
        time.sleep(4.0)
        env.close()
        print("CLOSED", flush=True)
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], env=xvfb, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        _wait_for(proc, "READY")
        img = screenshot(xvfb).astype(int)
        _wait_for(proc, "CLOSED")
    finally:
        proc.kill()
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    tissue = (r > g + 40) & (r > b + 40)                  # the liver slab's red-brown surface
    assert img.std() > 10, "the screen is blank"
    assert tissue.mean() > 0.005, f"no tissue-coloured pixels on screen ({tissue.mean():.4f})"
