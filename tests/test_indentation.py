"""Probe indentation of an anchored slab through the full MuJoCo + contact + tissue loop."""

import numpy as np
import pytest

from surgsim_envs.scene import ProbeConfig, SceneConfig, Simulation, TissueConfig, build_scene

TIP = 0.008
DEPTHS = (0.001, 0.002, 0.003, 0.004)  # m


@pytest.fixture(scope="module")
def indentation_curve():
    tissue = TissueConfig(name="slab", organ="slab", model="mass_spring", material="liver", spacing=0.005,
                          anchors=("bottom",), position=(0.0, 0.0, 0.01), volume_options={"size": (0.06, 0.06, 0.02)},
                          options={"integrator": "symplectic"})
    top = 0.02
    probe = ProbeConfig(name="probe", tip_radius=TIP, position=(0.0, 0.0, top + TIP + 0.001))
    sim = Simulation(build_scene(SceneConfig(name="indent", tissues=[tissue], tools=[probe], dt=5e-4,
                                             floor=False, cameras=[])))
    forces, pens, depths = [], [], []
    for depth in DEPTHS:
        sim.set_tool_target("probe", [0.0, 0.0, top + TIP - depth], speed=0.01)
        sim.run(0.25)  # reach the depth, then settle (quasi-static)
        rep = sim.contact_report()["probe"]
        forces.append(rep["normal_force"])
        pens.append(rep["penetration"])
        depths.append(top + TIP - sim.tool_position("probe")[2])  # actual tip depth below the rest surface
    return np.array(depths), np.array(forces), np.array(pens)


def test_force_grows_monotonically_and_stiffens(indentation_curve):
    depths, forces, _ = indentation_curve
    np.testing.assert_allclose(depths, DEPTHS, atol=2e-4)  # the position-driven probe reaches its targets
    assert forces[0] > 0
    assert np.all(np.diff(forces) > 0), f"force not monotonic in depth: {forces}"
    secant = forces / depths
    # a spherical tip's contact area grows with depth (Hertz: F ~ d^1.5), plus strain stiffening
    assert np.all(np.diff(secant) > 0), f"no stiffening: F/d = {secant}"
    assert forces[-1] / forces[1] > 1.1 * DEPTHS[-1] / DEPTHS[1]


def test_tip_penetration_is_below_ten_percent_of_depth(indentation_curve):
    depths, _, pens = indentation_curve
    assert np.all(pens < 0.1 * depths), f"penetration {pens * 1e3} mm at depths {depths * 1e3} mm"
