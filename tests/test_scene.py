"""Scene building, tools, the step loop API and bad input."""

import math

import numpy as np
import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.scene import (GrasperConfig, HapticProxyConfig, ProbeConfig, SceneConfig, Simulation,
                                TissueConfig, build_scene, grasp_config, grasp_scene, make_scene)


def small_tissue(**kw):
    base = dict(name="slab", organ="slab", model="mass_spring", material="liver", spacing=0.01, anchors=("bottom",),
                position=(0.0, 0.0, 0.01), volume_options={"size": (0.06, 0.06, 0.02)},
                options={"integrator": "symplectic"})
    base.update(kw)
    return TissueConfig(**base)


def probe_sim(**probe_kw):
    probe = ProbeConfig(**{"name": "probe", "tip_radius": 0.008, "position": (0.0, 0.0, 0.03), **probe_kw})
    proxies = [HapticProxyConfig(name="hand", tool="probe")] if probe.drive == "proxy" else []
    return Simulation(build_scene(SceneConfig(name="t", tissues=[small_tissue()], tools=[probe], proxies=proxies,
                                              dt=5e-4, cameras=[])))


# ------------------------------------------------------------------------------------------------
# bad input
def test_unknown_tool_and_tissue_names_raise_config_error():
    sim = probe_sim()
    with pytest.raises(ConfigError, match="unknown tool 'scalpel'.*probe"):
        sim.set_tool_target("scalpel", [0, 0, 0.03])
    with pytest.raises(ConfigError, match="unknown tissue 'kidney'"):
        sim.tissue("kidney")
    with pytest.raises(ConfigError, match="unknown volume|unknown organ|'pancreas'"):
        build_scene(SceneConfig(tissues=[small_tissue(organ="pancreas")], cameras=[]))
    with pytest.raises(ConfigError, match="unknown tissue model"):
        build_scene(SceneConfig(tissues=[small_tissue(model="no_such_model")], cameras=[]))
    with pytest.raises(ConfigError, match="unknown scene"):
        make_scene("appendectomy")
    with pytest.raises(ConfigError, match="does not exist"):
        build_scene(SceneConfig(tools=[ProbeConfig(drive="proxy")], proxies=[HapticProxyConfig(tool="scalpel")]))


def test_tissue_inside_a_tool_is_rejected():
    with pytest.raises(ConfigError, match="starts inside tool 'probe'"):
        probe_sim(position=(0.0, 0.0, 0.02))  # tip centre on the top face


@pytest.mark.parametrize("dt, substeps", [(0.0, 1), (0.1, 1), (float("nan"), 1), (1e-3, 0), (1e-3, 2.5), (1e-3, 10**6)])
def test_dt_and_substeps_out_of_range(dt, substeps):
    cfg = SceneConfig(tissues=[small_tissue()], dt=dt, substeps=substeps, cameras=[])
    with pytest.raises(ConfigError, match="dt=|substeps="):
        build_scene(cfg)


def test_simulation_rejects_bad_dt_override_and_unreachable_targets():
    scene = build_scene(SceneConfig(tissues=[small_tissue()], tools=[ProbeConfig(position=(0, 0, 0.03))],
                                    dt=5e-4, cameras=[]))
    with pytest.raises(ConfigError, match="dt="):
        Simulation(scene, dt=1.0)
    sim = Simulation(scene)
    with pytest.raises(ConfigError, match="outside tool 'probe'"):
        sim.set_tool_target("probe", [5.0, 0.0, 0.03])
    with pytest.raises(ConfigError, match="is a probe; it has no command .set_jaw_opening"):
        sim.set_jaw_opening("probe", 0.01)


# ------------------------------------------------------------------------------------------------
# tools
def test_probe_follows_its_target_at_the_set_speed():
    sim = probe_sim()
    sim.set_tool_target("probe", [0.01, 0.0, 0.03], speed=0.02)
    sim.run(0.25)  # 5 mm at 20 mm/s
    assert sim.tool_position("probe")[0] == pytest.approx(0.005, abs=3e-4)
    sim.run(0.5)
    assert sim.tool_position("probe")[0] == pytest.approx(0.01, abs=2e-4)


def test_grasper_jaws_close_in_parallel_at_the_set_speed():
    cfg = SceneConfig(name="g", tools=[GrasperConfig(position=(0.0, 0.0, 0.1), axis=(0, 0, -1), open_radius=0.03)],
                      cameras=[])
    sim = Simulation(build_scene(cfg))
    tool = sim.tool("grasper")
    sim.set_jaw_opening("grasper", 0.015, speed=0.01)
    sim.run(0.5)  # 5 mm at 10 mm/s
    q = sim.data.qpos[tool.jaw_qpos_adr]
    np.testing.assert_allclose(q, q[0], atol=1e-5)   # the three jaws move together
    assert sim.jaw_opening("grasper") == pytest.approx(0.025, abs=3e-4)
    sim.run(1.5)
    assert sim.jaw_opening("grasper") == pytest.approx(0.015, abs=2e-4)
    # jaws sit at 120 degrees about the axis, all at the same distance from it
    axis_pt = sim.tool_position("grasper")[:2]
    r = np.linalg.norm(sim.data.xpos[tool.jaw_body_ids][:, :2] - axis_pt, axis=1)
    np.testing.assert_allclose(r, r[0], rtol=1e-4)
    v = sim.data.xpos[tool.jaw_body_ids][:, :2] - axis_pt
    cosines = [v[i] @ v[(i + 1) % 3] / (r[0] ** 2) for i in range(3)]
    np.testing.assert_allclose(cosines, math.cos(2 * math.pi / 3), atol=1e-3)


def test_haptic_proxy_feels_the_tissue_push_back():
    sim = probe_sim(drive="proxy")
    sim.set_proxy_pose("hand", [0.0, 0.0, 0.025])  # 3 mm into the surface (tip bottom at 0.017)
    sim.run(0.4)
    felt = sim.proxy_force("hand")
    contact = sim.tool_force("probe")
    assert felt[2] > 0.01, f"the hand should be pushed up, felt {felt}"
    # quasi-static: the coupling balances the contact force on the tool
    assert felt[2] == pytest.approx(contact[2], rel=0.1)
    assert sim.tool_position("probe")[2] > 0.025  # the tool lags above the proxy (virtual coupling)


def test_reset_restores_the_initial_state():
    sim = probe_sim()
    x0 = sim.tissue_positions().copy()
    sim.set_tool_target("probe", [0.0, 0.0, 0.024], speed=0.05)
    sim.run(0.3)
    assert sim.contact_report()["probe"]["contacts"] > 0
    sim.reset()
    assert sim.time == 0.0
    np.testing.assert_array_equal(sim.tissue_positions(), x0)
    np.testing.assert_allclose(sim.tool_position("probe"), [0.0, 0.0, 0.03])
    assert sim.contact_report()["probe"]["normal_force"] == 0.0


def test_same_seed_same_trajectory():
    def run():
        sim = probe_sim()
        sim.set_tool_target("probe", [0.002, 0.0, 0.024], speed=0.05)
        sim.run(0.2)
        return sim.tissue_positions(), sim.tool_position("probe")
    a, b = run(), run()
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])


def test_grasper_pull_leads_to_gross_slip_at_low_friction_only():
    """The grasping simulation paper: the same pull holds the tissue with high friction and slides off with low friction."""
    def pulled(mu):
        cfg = grasp_config()
        cfg.tissues[0].spacing = 0.009
        cfg.tool("grasper").friction = mu
        sim = Simulation(grasp_scene(cfg))
        tool = sim.tool("grasper")
        sim.set_jaw_opening("grasper", 0.012, speed=0.05)
        sim.run(0.6)
        tissue = sim.tissue()
        tip = np.flatnonzero(tissue.positions[:, 0] > tissue.positions[:, 0].max() - 0.01)
        x0 = tissue.positions[tip, 0].mean()
        sim.set_tool_target("grasper", tool.home + [0.01, 0.0, 0.0], speed=0.02)
        sim.run(0.6)
        return tissue.positions[tip, 0].mean() - x0   # how far the grasped tip followed the 10 mm pull
    assert pulled(2.0) > 2.0 * pulled(0.05)
