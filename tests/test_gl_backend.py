"""A missing or unknown OpenGL backend (MUJOCO_GL) does not stop the physics; rendering then
raises an error naming the backend, its Debian package and the alternatives."""

from __future__ import annotations

import os
import subprocess
import sys

from surgsim_envs.scene.gl_backend import gl_problem

def test_problem_names_the_backend_its_package_and_the_alternatives():
    msg = gl_problem("osmesa", AttributeError("'NoneType' object has no attribute 'glGetError'"))
    assert "MUJOCO_GL='osmesa'" in msg and "apt-get install libosmesa6" in msg
    assert "MUJOCO_GL=egl (apt-get install libegl1" in msg and "--no-video" in msg
    assert "MUJOCO_GL=osmesa (" not in msg                     # the failed backend is not offered again
    msg = gl_problem("egl", OSError("libEGL.so.1: cannot open shared object file"))
    assert "apt-get install libegl1" in msg and "MUJOCO_GL=osmesa (apt-get install libosmesa6" in msg
    assert "is not a backend MuJoCo knows" in gl_problem("nonsense", RuntimeError("invalid value"))


def test_physics_runs_and_rendering_says_why_when_the_backend_cannot_load():
    """MUJOCO_GL names a backend MuJoCo cannot load (an unknown one: the same on every host):
    before, ``import mujoco`` raised; now the physics steps and the renderer names the fix."""
    code = (
        "import surgsim_envs.scene as scene, mujoco\n"
        "from surgsim_envs.errors import RenderingUnavailableError\n"
        "from surgsim_envs.scene.render import SceneRenderer\n"
        "m = mujoco.MjModel.from_xml_string('<mujoco><worldbody><body><freejoint/><geom size=\".1\"/></body>"
        "</worldbody></mujoco>')\n"
        "d = mujoco.MjData(m)\n"
        "[mujoco.mj_step(m, d) for _ in range(10)]\n"
        "assert d.qpos[2] < 0\n"
        "try:\n"
        "    SceneRenderer(None)\n"
        "except RenderingUnavailableError as exc:\n"
        "    print('ERROR', exc)\n")
    env = dict(os.environ, MUJOCO_GL="nonsense")
    raw = subprocess.run([sys.executable, "-c", "import mujoco"], env=env, capture_output=True, text=True)
    assert raw.returncode != 0 and "MUJOCO_GL" in raw.stderr          # what users saw before
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "ERROR MuJoCo could not load the OpenGL backend MUJOCO_GL='nonsense'" in out.stdout
    assert "MUJOCO_GL=egl (apt-get install libegl1" in out.stdout and "--no-video" in out.stdout
