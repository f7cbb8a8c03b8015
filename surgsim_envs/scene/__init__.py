"""MuJoCo scenes: tools built with MjSpec, tissue binding (flex), the step loop, rendering.

>>> from surgsim_envs.scene import Simulation, palpation_scene
>>> sim = Simulation(palpation_scene())                       # doctest: +SKIP
>>> sim.set_tool_target("probe", [0, 0, 0.015], speed=0.01)    # doctest: +SKIP
>>> sim.run(1.0); sim.contact_report()["probe"]               # doctest: +SKIP

Headless rendering: if ``MUJOCO_GL`` is unset and there is no display, this package sets
``MUJOCO_GL=egl`` before MuJoCo is first imported (set it yourself to ``osmesa`` if EGL is missing).
If the backend's library is missing, MuJoCo is imported without OpenGL and rendering raises
RenderingUnavailableError naming the backend and its package (scene/gl_backend.py).
"""

import os
import sys

if "MUJOCO_GL" not in os.environ and sys.platform.startswith("linux") and not os.environ.get("DISPLAY") \
        and "mujoco" not in sys.modules:
    os.environ["MUJOCO_GL"] = "egl"

from surgsim_envs.scene.gl_backend import import_mujoco  # noqa: E402

import_mujoco()   # a missing OpenGL library must not stop the physics (scene/gl_backend.py)

from surgsim_envs.scene.builder import (SCENES, Scene, build_scene, grasp_config, grasp_scene,  # noqa: E402
                                        make_scene, palpation_config, palpation_scene, register_scene, scene_config)
from surgsim_envs.scene.config import (CameraConfig, ContactConfig, GrasperConfig, HapticProxyConfig,  # noqa: E402
                                       ProbeConfig, SceneConfig, TissueConfig)
from surgsim_envs.scene.simulation import Simulation  # noqa: E402

__all__ = ["SCENES", "Scene", "Simulation", "build_scene", "make_scene", "scene_config", "register_scene", "palpation_scene", "palpation_config", "grasp_scene",
           "grasp_config", "SceneConfig", "TissueConfig", "ProbeConfig", "GrasperConfig", "HapticProxyConfig",
           "CameraConfig", "ContactConfig"]
