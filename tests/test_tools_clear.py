"""Tools start clear of all geometry; at rest the hand feels nothing."""

import mujoco
import numpy as np
import pytest

from surgsim_envs.errors import ConfigError


@pytest.mark.parametrize("task", ["palpation", "grasp"])
def test_felt_force_at_rest_is_below_one_millinewton(task):
    """Proxy at home, nothing touched: the weld force the hand feels stays < 1 mN (it was ~9 N in the
    grasp scene, whose lower jaws started 2 mm inside the floor)."""
    from surgsim_envs.haptics.scene_adapter import make_haptic_simulation

    physics = make_haptic_simulation(task, spacing=0.012 if task == "grasp" else 0.01)
    peak = 0.0
    for _ in range(int(0.2 / physics.dt)):
        physics.step()
        peak = max(peak, float(np.linalg.norm(physics.coupling_force())))
    assert peak < 1e-3, f"{task}: felt {peak:.3g} N at rest"
    assert physics.sim.data.ncon == 0


@pytest.mark.parametrize("organ", ["spleen", "liver_lobe"])
def test_grasp_scene_tools_clear_of_the_floor(organ):
    from surgsim_envs.scene import Simulation, grasp_config, grasp_scene

    cfg = grasp_config(organ=organ)
    cfg.tissues[0].spacing = 0.015
    sim = Simulation(grasp_scene(cfg))
    mujoco.mj_forward(sim.model, sim.data)
    assert sim.data.ncon == 0


def test_tool_inside_the_floor_is_rejected_by_name():
    from surgsim_envs.scene import build_scene, grasp_config
    from surgsim_envs.scene.builder import lowest_jaw_point, place_grasper_around_tip, placed_volume

    cfg = grasp_config()
    cfg.tissues[0].spacing = 0.015
    cfg.tissues[0].position = (0.0, 0.0, 0.02)     # jaws around the tip reach below z = 0
    g = place_grasper_around_tip(placed_volume(cfg.tissues[0]).nodes, cfg.tool("grasper"))
    cfg.replace_tool("grasper", g)
    assert lowest_jaw_point(g) < 0
    with pytest.raises(ConfigError, match=r"tool 'grasper' starts inside 'floor': geom 'grasper/jaw\d_box' penetrates"):
        build_scene(cfg)


def test_lowest_jaw_point_matches_mujoco():
    from surgsim_envs.scene import Simulation, grasp_config, grasp_scene
    from surgsim_envs.scene.builder import lowest_jaw_point

    cfg = grasp_config()
    cfg.tissues[0].spacing = 0.015
    sim = Simulation(grasp_scene(cfg))
    g = sim.tool("grasper")
    m, d = sim.model, sim.data
    mujoco.mj_forward(m, d)
    low = np.inf
    for gid in g.jaw_geom_ids:
        half, rot, pos = m.geom_size[gid], d.geom_xmat[gid].reshape(3, 3), d.geom_xpos[gid]
        low = min(low, pos[2] - np.abs(rot[2]) @ half)
    assert abs(lowest_jaw_point(g.config) - low) < 1e-9
    assert low >= 1e-3 - 1e-9                      # FLOOR_CLEARANCE
