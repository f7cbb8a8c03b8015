"""The interactive paths as a person uses them, under a virtual display (Xvfb): the MuJoCo viewer
with render_mode="human", `surgsim teleop palpation --device keyboard` driven by synthetic key
events (xdotool), `surgsim run ... --viewer` and dm_control's viewer on the dm_control suite, each checked by a screenshot that shows the scene.
Skips with a reason where Xvfb / xdotool / xwd are absent (Debian: apt-get install xvfb xdotool
x11-apps; .ci/run installs them when it runs as root).

The screen is 1280x1024: MuJoCo's viewer opens at 2/3 of the screen. The package opens it with
MuJoCo's two UI panels hidden (they would cover most of the 3D view; Tab / Shift+Tab show them)."""

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
    proc = subprocess.Popen(["Xvfb", display, "-screen", "0", "1280x1024x24", "-nolisten", "tcp"],
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


@pytest.mark.slow
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
    tissue = _tissue(img)                  # the slab, coloured by displacement, seen through the task's camera
    assert img.std() > 10, "the screen is blank"
    assert tissue.mean() > 0.02, f"the tissue fills too little of the screen ({tissue.mean():.4f})"


def _window(env, name: str = "MuJoCo", timeout: float = 240.0) -> str:
    t0 = time.time()
    while time.time() - t0 < timeout:
        out = subprocess.run(["xdotool", "search", "--name", name], env=env, capture_output=True, text=True).stdout
        if out.split():
            return out.split()[0]
        time.sleep(0.5)
    raise AssertionError(f"no window named {name!r} appeared within {timeout:.0f} s")


def _xdotool(env, *args) -> None:
    subprocess.run(["xdotool", *args], env=env, check=True, timeout=30, capture_output=True)


def _focus(env, win: str, timeout: float = 20.0) -> None:
    """Give ``win`` the keyboard focus (retried: it fails until the window is mapped)."""
    t0 = time.time()
    while subprocess.run(["xdotool", "windowfocus", "--sync", win], env=env, capture_output=True,
                         timeout=30).returncode != 0:
        assert time.time() - t0 < timeout, f"window {win} never took the keyboard focus"
        time.sleep(0.5)


def _framed(env, timeout: float = 60.0) -> np.ndarray:
    """Screenshots until the viewer shows the tissue large (framed camera, panels hidden)."""
    t0 = time.time()
    while True:
        img = screenshot(env).astype(int)
        if _tissue(img).mean() > 0.02 or time.time() - t0 > timeout:
            return img
        time.sleep(1.0)


def _tissue(img: np.ndarray) -> np.ndarray:
    """Strongly coloured pixels: the tissue (colour map), not the grey floor, sky, probe or panels."""
    return img.max(axis=-1) - img.min(axis=-1) > 60


def _probe_bottom(img: np.ndarray, cols) -> int:
    """Lowest screen row of the white probe within the tissue's columns."""
    white = (img.min(axis=-1) > 200)[:, cols[0]:cols[1]]
    rows = np.nonzero(white.any(axis=1))[0]
    assert len(rows), "no white probe pixels above the tissue"
    return int(rows.max())


def test_teleop_keyboard_moves_the_probe(xvfb):
    """Page Down x8 moves the keyboard handle 8 mm down (1 mm a press): the probe presses the
    tissue (a felt force), goes lower on screen, and the run ends at --duration (15 s: the keys and
    the screenshots take about 5 s after the window opens)."""
    proc = subprocess.Popen([sys.executable, "-m", "surgsim_envs.cli", "teleop", "palpation", "--device", "keyboard",
                             "--duration", "15"], env=xvfb, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        win = _window(xvfb)
        t_open = time.time()
        _focus(xvfb, win)
        before = _framed(xvfb)
        _xdotool(xvfb, "key", "--delay", "100", *(["Next"] * 8))   # Page Down: -z, 1 mm each
        time.sleep(3.0)
        after = _framed(xvfb)
        assert time.time() - t_open < 13, "the keys came too late for the 15 s run; the machine is too slow"
        out, err = proc.communicate(timeout=120)          # --duration bounds the run
    finally:
        proc.kill()
    assert proc.returncode == 0, f"teleop failed ({proc.returncode}):\n{out}\n{err}"
    assert "Segmentation fault" not in err
    assert "keyboard: 8 keys handled" in out, out
    assert "handle at (+0.0000, +0.0000, -0.0080) m" in out, out
    force = float(out.split("max force ")[1].split(" N")[0])
    assert force > 0.05, f"the probe pressed 8 mm down but felt {force} N:\n{out}"
    tissue = _tissue(after)
    assert after.std() > 10 and tissue.mean() > 0.02, f"the tissue is not on screen ({tissue.mean():.4f})"
    cols = np.nonzero(tissue.any(axis=0))[0]
    span = (int(cols.min()), int(cols.max()) + 1)
    moved = _probe_bottom(after, span) - _probe_bottom(before, span)
    assert moved >= 5, f"the probe moved {moved} px down on screen after 8 mm of Page Down"


@pytest.mark.slow
def test_run_scenario_with_viewer(xvfb, tmp_path):
    """`surgsim run TASK.toml --viewer` opens the viewer on the tissue, plays the scenario at real
    time (3.3 s at --duration-scale 0.3: long enough for the screenshot, even on a loaded machine)
    and finishes it."""
    toml = os.path.join(os.path.dirname(__file__), "..", "tasks", "palpation_find_inclusion.toml")
    t0 = time.time()
    proc = subprocess.Popen([sys.executable, "-m", "surgsim_envs.cli", "run", toml, "--viewer", "--duration-scale",
                             "0.3", "--no-video", "--quiet", "--out", str(tmp_path)],
                            env=xvfb, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        win = _window(xvfb)
        _focus(xvfb, win)
        img = _framed(xvfb, timeout=30)
        out, err = proc.communicate(timeout=300)
        wall = time.time() - t0
    finally:
        proc.kill()
    assert proc.returncode == 0, f"surgsim run --viewer failed ({proc.returncode}):\n{out}\n{err}"
    assert wall >= 3.3, f"the 3.3 s scenario played in {wall:.1f} s: the viewer must play at real time, not faster"
    assert "Segmentation fault" not in err
    assert "surgsim run: palpation_find_inclusion: score" in out, out
    assert (tmp_path / "report.json").is_file()
    tissue = _tissue(img)
    assert img.std() > 10 and tissue.mean() > 0.02, f"the tissue is not on screen ({tissue.mean():.4f})"


@pytest.mark.slow
def test_dm_control_viewer_runs_palpation(xvfb):
    """dm_control.viewer.launch on surgsim_envs.integrations.dm_control.load("palpation"): the window
    ("Explorer", glfw) shows the tissue; Space un-pauses it and the viewer steps the environment
    through the policy. viewer.launch blocks until its window closes, so the test ends the child."""
    code = textwrap.dedent("""
        import numpy as np
        from dm_control import viewer
        import surgsim_envs.integrations.dm_control as suite
        env = suite.load("palpation")
        spec = env.action_spec()
        calls = []
        def policy(time_step):
            calls.append(1)
            if len(calls) == 3:
                print("STEPPED", flush=True)
            return np.zeros(spec.shape, spec.dtype)
        viewer.launch(env, policy=policy)
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], env=xvfb, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        win = _window(xvfb, "Explorer")
        _focus(xvfb, win)
        time.sleep(2.0)
        _xdotool(xvfb, "key", "space")                 # the viewer starts paused
        _wait_for(proc, "STEPPED", timeout=120)
        img = _framed(xvfb, timeout=30)
    finally:
        proc.kill()
        proc.wait(timeout=30)
    tissue = _tissue(img)
    assert img.std() > 10 and tissue.mean() > 0.02, f"the tissue is not on screen ({tissue.mean():.4f})"
