"""Tools as plugins: a scene from a list of tools; a new kind is one module + one registration."""

import sys
import types
from dataclasses import dataclass

import mujoco
import numpy as np
import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.scene import GrasperConfig, ProbeConfig, SceneConfig, Simulation, TissueConfig, build_scene


def _slab():
    return TissueConfig(name="slab", organ="slab", spacing=0.01, material="liver", anchors=("bottom",),
                        position=(0.0, 0.0, 0.01), volume_options={"size": (0.1, 0.1, 0.02)},
                        options={"integrator": "symplectic"})


def test_scene_with_two_probes_and_a_grasper_from_one_list():
    cfg = SceneConfig(name="three", tissues=[_slab()], dt=5e-4, cameras=[], tools=[
        ProbeConfig(name="left", tip_radius=0.006, position=(-0.025, 0.0, 0.028)),
        ProbeConfig(name="right", tip_radius=0.006, position=(0.025, 0.0, 0.028)),
        GrasperConfig(name="jaws", position=(0.0, 0.0, 0.12), axis=(0.0, 0.0, -1.0), open_radius=0.02)])
    sim = Simulation(build_scene(cfg))
    assert list(sim.tools) == ["left", "right", "jaws"]
    # press only the left probe 4 mm into the slab top (z = 0.02): it alone feels the tissue, upwards
    sim.set_tool_target("left", [-0.025, 0.0, 0.02 + 0.006 - 0.004], speed=0.05)
    sim.set_jaw_opening("jaws", 0.01, speed=0.05)
    sim.run(0.4)
    f_left, f_right, f_jaws = (sim.tool_force(n) for n in ("left", "right", "jaws"))
    assert f_left[2] > 0.05 and f_left[2] > 5 * abs(f_left[:2]).max()       # mostly upward (coarse lattice)
    assert np.allclose(f_right, 0.0) and np.allclose(f_jaws, 0.0)
    assert abs(sim.jaw_opening("jaws") - 0.01) < 5e-4           # the grasper's own command worked
    with pytest.raises(ConfigError, match="tool 'right' is a probe; it has no command 'set_jaw_opening'"):
        sim.set_jaw_opening("right", 0.01)


def test_a_new_tool_kind_is_one_module_and_one_registration():
    """A 'needle' (a thin capsule on three slides) registered from outside the package."""
    from surgsim_envs.scene.tools import ToolSpec, register_tool
    from surgsim_envs.scene.tools.base import TOOL_CONAFFINITY, TOOL_CONTYPE, _slide_drive

    @dataclass
    class NeedleConfig:
        name: str = "needle"
        position: tuple = (0.0, 0.0, 0.05)
        radius: float = 0.0005
        length: float = 0.05
        drive: str = "position"
        kp: float = 2e4
        dampratio: float = 1.0
        speed: float = np.inf
        travel: float = 0.1
        friction: float | None = None

    mod = types.ModuleType("needle_plugin_for_test")
    mod.KIND = "needle"

    def validate(c):
        if c.radius <= 0:
            raise ConfigError(f"needle '{c.name}' radius must be > 0 m, got {c.radius!r}")

    def build(spec, c):
        body = spec.worldbody.add_body(name=c.name, pos=list(c.position), gravcomp=1.0, mass=0.01,
                                       inertia=[1e-6] * 3, explicitinertial=True)
        joints, acts = _slide_drive(spec, body, c.name, np.eye(3), c, 0.01, c.travel)
        geom = f"{c.name}/shaft"
        body.add_geom(name=geom, type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[c.radius, c.length / 2, 0],
                      pos=[0, 0, c.length / 2], contype=TOOL_CONTYPE, conaffinity=TOOL_CONAFFINITY, mass=0, density=0)
        return ToolSpec(name=c.name, kind=mod.KIND, config=c, body=c.name, contact_geoms=[geom], joints=joints,
                        actuators=acts, home=np.asarray(c.position, dtype=float))

    mod.validate, mod.build = validate, build
    sys.modules[mod.__name__] = mod
    try:
        register_tool(NeedleConfig, mod.__name__)
        cfg = SceneConfig(tissues=[_slab()], dt=5e-4, cameras=[], tools=[NeedleConfig(position=(0.0, 0.0, 0.021))])
        sim = Simulation(build_scene(cfg))
        sim.set_tool_target("needle", [0.0, 0.0, 0.016], speed=0.05)
        sim.run(0.3)
        assert sim.tool_force("needle")[2] > 0.0              # the tissue pushes the needle back up
        with pytest.raises(ConfigError, match="needle 'needle' radius must be > 0 m"):
            build_scene(SceneConfig(tissues=[_slab()], cameras=[], tools=[NeedleConfig(radius=0.0)]))
    finally:
        sys.modules.pop(mod.__name__, None)


def test_unregistered_tool_config_is_named():
    @dataclass
    class Scalpel:
        name: str = "scalpel"

    with pytest.raises(ConfigError, match="Scalpel is not a registered tool config"):
        build_scene(SceneConfig(tools=[Scalpel()], cameras=[]))
