"""Action = reaction across the MuJoCo/tissue boundary: total linear momentum is conserved."""

import numpy as np

from surgsim_envs.scene import ProbeConfig, SceneConfig, Simulation, TissueConfig, build_scene

# no nodal damping (an absolute damper is an external force) and no anchors or gravity
FREE_MATERIAL = {"preset": "liver", "damping": 0.0}


def _free_scene(speed=-0.4):
    tissue = TissueConfig(name="blob", organ="block", model="mass_spring", material=FREE_MATERIAL, spacing=0.01,
                          anchors=(), position=(0.0, 0.0, 0.0), volume_options={"size": (0.04, 0.04, 0.02)},
                          options={"integrator": "symplectic"})
    probe = ProbeConfig(name="probe", drive="free", tip_radius=0.008, position=(0.003, -0.002, 0.0185), mass=0.02)
    cfg = SceneConfig(name="momentum", tissues=[tissue], tools=[probe], dt=5e-4, gravity=(0.0, 0.0, 0.0),
                      floor=False, cameras=[])
    sim = Simulation(build_scene(cfg))
    sim.data.qvel[sim.tool("probe").dof_adr[2]] = speed  # moving down onto the tissue
    return sim


def test_total_momentum_is_conserved_through_an_impact():
    sim = _free_scene()
    p0 = sim.momentum()
    assert abs(p0[2]) > 1e-3  # the tool carries the momentum at first
    touched = 0
    for _ in range(400):
        sim.physics_step()
        touched += sim.contact_report()["probe"]["contacts"] > 0
    p1 = sim.momentum()
    tissue_p = sim.tissue().momentum()
    assert touched > 10, "the tool never hit the tissue"
    assert abs(tissue_p[2]) > 0.2 * abs(p0[2]), "the impact did not transfer momentum to the tissue"
    np.testing.assert_allclose(p1, p0, atol=1e-9 * max(1.0, np.abs(p0).max()) + 1e-12)


def test_reaction_is_applied_then_cleared():
    sim = _free_scene()
    body = sim.tool("probe").body_id
    for _ in range(200):
        sim.physics_step()
        assert np.all(sim.data.xfrc_applied[body] == 0.0)  # cleared after mj_step2
    # the last step's reaction equals minus the force put on the tissue
    res = sim.contacts["blob"].result
    np.testing.assert_allclose(sim.tool_force("probe"), -res.forces.sum(axis=0), atol=1e-12)
