"""Offscreen rendering: the tissue flex shows the dent the probe makes; MP4 output."""

import numpy as np
import pytest

from surgsim_envs.errors import RenderingUnavailableError
from surgsim_envs.scene import CameraConfig, ProbeConfig, SceneConfig, Simulation, TissueConfig, build_scene


def _renderer(sim):
    from surgsim_envs.scene.render import SceneRenderer

    try:
        return SceneRenderer(sim, 160, 120)
    except RenderingUnavailableError as exc:
        pytest.skip(f"no OpenGL for offscreen rendering here: {exc}")


@pytest.fixture(scope="module")
def sim():
    tissue = TissueConfig(name="slab", organ="slab", spacing=0.005, anchors=("bottom",), position=(0.0, 0.0, 0.01),
                          volume_options={"size": (0.06, 0.06, 0.02)}, options={"integrator": "symplectic"})
    probe = ProbeConfig(name="probe", tip_radius=0.008, position=(0.0, 0.0, 0.029), rgba=(0.2, 0.9, 0.2, 1.0))
    cams = [CameraConfig("top", (0.0, -0.0001, 0.12), (0.0, 0.0, 0.0), fovy=40.0)]
    return Simulation(build_scene(SceneConfig(name="render", tissues=[tissue], tools=[probe], dt=5e-4,
                                              cameras=cams, floor=True)))


def test_frame_shows_the_dent(sim):
    r = _renderer(sim)
    rest = r.render("top")
    assert rest.shape == (120, 160, 3) and rest.dtype == np.uint8
    sim.set_tool_target("probe", [0.0, 0.0, 0.022], speed=0.02)  # 5 mm into the surface
    sim.run(0.5)
    tissue = sim.tissue()
    assert tissue.positions[:, 2].min() < tissue.rest_positions[:, 2].max()
    dented = r.render("top")
    # same tool pose, tissue drawn at rest: the only difference is the dent
    saved = tissue.positions.copy()
    tissue.positions[:] = tissue.rest_positions
    flat = r.render("top")
    tissue.positions[:] = saved
    diff = np.abs(dented.astype(int) - flat.astype(int)).sum(axis=2) > 24
    assert diff.sum() > 20, "the rendered tissue did not change where the probe pressed"
    # the change lies around the probe (image centre), not across the whole slab
    ys, xs = np.nonzero(diff)
    assert np.all(np.abs(xs - 80) < 60) and np.all(np.abs(ys - 60) < 50)
    assert np.abs(dented.astype(int) - rest.astype(int)).sum() > 0
    r.close()


def test_unknown_camera_and_video(sim, tmp_path):
    from surgsim_envs.errors import ConfigError
    from surgsim_envs.scene.render import VideoWriter

    r = _renderer(sim)
    with pytest.raises(ConfigError, match="unknown camera"):
        r.render("nope")
    path = tmp_path / "v.mp4"
    with VideoWriter(path, 25, (160, 120)) as w:
        for _ in range(3):
            sim.physics_step()
            w.write(r.render("top"))
    r.close()
    assert path.stat().st_size > 0
    import cv2

    cap = cv2.VideoCapture(str(path))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 3


def test_missing_gl_raises_a_clear_error(sim, monkeypatch):
    import mujoco

    from surgsim_envs.scene.render import SceneRenderer

    def no_gl(*a, **k):
        raise RuntimeError("Failed to initialize OpenGL")

    monkeypatch.setattr(mujoco, "Renderer", no_gl)
    with pytest.raises(RenderingUnavailableError, match="MUJOCO_GL=egl.*osmesa"):
        SceneRenderer(sim, 160, 120)
