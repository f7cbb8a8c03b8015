"""The tissue surfaces live only in the render twin (scene/visual.py), never in the physics model."""

import numpy as np


def test_physics_model_has_no_flex_and_render_twin_shows_the_deformed_surface():
    from surgsim_envs.scene import Simulation, palpation_config, palpation_scene

    cfg = palpation_config(organ="slab")
    cfg.tissues[0].spacing = 0.01
    cfg.tissues[0].region_materials = None
    sim = Simulation(palpation_scene(cfg))
    assert sim.model.nflex == 0                    # mj_step1 never recomputes visual geometry
    assert sim.render_model.nflex == 1
    # same ids in both models: the twin's bodies sit where the physics put them
    sim.set_tool_target("probe", [0.01, 0.0, 0.03], speed=0.5)
    sim.run(0.05)
    data = sim.sync_visual()
    np.testing.assert_allclose(data.xpos, sim.data.xpos, atol=1e-12)
    np.testing.assert_allclose(data.qpos, sim.data.qpos, atol=0)
    binding = sim.bindings["slab"]
    tissue = sim.tissue()
    tissue.positions[:] = tissue.rest_positions + [0.0, 0.0, 0.002]
    data = sim.sync_visual()
    verts = data.flexvert_xpos[binding.vertadr:binding.vertadr + binding.n_vertices]
    np.testing.assert_allclose(verts, binding.vertex_positions(), atol=1e-12)
    lo = float(verts[:, 2].min())
    tissue.positions[:] = tissue.rest_positions
    data = sim.sync_visual()
    verts = data.flexvert_xpos[binding.vertadr:binding.vertadr + binding.n_vertices]
    assert np.isclose(lo - float(verts[:, 2].min()), 0.002, atol=1e-9)   # the written surface follows the nodes
