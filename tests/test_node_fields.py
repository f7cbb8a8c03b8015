"""Per-node scalar fields for display (contract v2) and the surface coloured by one."""

import dataclasses

import numpy as np
import pytest

from surgsim_envs import geometry, tissue
from surgsim_envs.errors import ConfigError
from surgsim_envs.tissue.base import von_mises
from surgsim_envs.tissue.fem_assembly import lame_parameters

EPS = 1e-3
ELASTIC = {"preset": "liver", "relax_fraction": 0.0, "nonlinear": 0.0}


def _compressed(name):
    vol = geometry.box_volume((0.04, 0.04, 0.04), spacing=0.005)
    m = tissue.make(name, vol, ELASTIC)
    x, c = m.rest_positions, m.rest_positions.mean(axis=0)
    f = np.diag([1.0, 1.0, 1.0 - EPS])
    m.positions = (x - c) @ f.T + c
    inner = np.all(np.abs(x - c) < 0.012, axis=1)
    return m, f, inner


@pytest.mark.parametrize("name", ["mass_spring", "fem"])
def test_every_model_gives_displacement_and_stress(name):
    vol = geometry.box_volume((0.02, 0.02, 0.02), spacing=0.005)
    m = tissue.make(name, vol, "liver")
    assert {"displacement", "stress"} <= set(m.field_names())
    fields = m.node_fields()
    assert all(v.shape == (m.n_nodes,) for v in fields.values())
    assert np.all(fields["displacement"] == 0) and np.allclose(fields["stress"], 0, atol=1e-9)
    m.positions = m.positions + np.array([0.001, 0.0, 0.0])          # rigid shift: moved, unstressed
    assert np.allclose(m.node_field("displacement"), 0.001)
    assert np.allclose(m.node_field("stress"), 0, atol=1e-9)
    with pytest.raises(ConfigError, match=r"fields: \['displacement', 'stress'"):
        m.node_field("temperature")


def test_fem_stress_is_the_von_mises_of_linear_elasticity():
    # confined uniaxial strain eps: sigma_zz - sigma_xx = 2 mu eps, von Mises = 2 mu eps
    m, _, inner = _compressed("fem")
    mu = lame_parameters(np.array([4000.0]), np.array([0.45]))[0][0]
    np.testing.assert_allclose(m.node_field("stress")[inner], 2 * mu * EPS, rtol=1e-9)


def test_mass_spring_stress_is_the_network_stress():
    # the node virial equals the stress from the energy derivative, sigma = dW/dF / V (Cauchy-Born)
    m, f0, inner = _compressed("mass_spring")
    x, c = m.rest_positions, m.rest_positions.mean(axis=0)
    vol = m.volume.total_volume()
    sig, h = np.zeros((3, 3)), 1e-7
    for i in range(3):
        for j in range(3):
            e = np.zeros((3, 3))
            e[i, j] = h
            w = []
            for s in (1, -1):
                m.positions = (x - c) @ (f0 + s * e).T + c
                w.append(m.elastic_energy())
            sig[i, j] = (w[0] - w[1]) / (2 * h) / vol
    m.positions = (x - c) @ f0.T + c
    np.testing.assert_allclose(m.node_field("stress")[inner], von_mises(sig[None])[0], rtol=5e-3)


def test_surface_coloured_by_a_field_shows_the_press():
    from surgsim_envs.errors import RenderingUnavailableError
    from surgsim_envs.scene import Simulation, build_scene
    from surgsim_envs.scene.builder import palpation_config

    cfg = palpation_config()
    cfg.tissues[0] = dataclasses.replace(cfg.tissues[0], render_field="displacement", render_range=(0.0, 0.004))
    sim = Simulation(build_scene(cfg))
    try:
        from surgsim_envs.scene.render import SceneRenderer
        renderer = SceneRenderer(sim, 640, 480)
    except RenderingUnavailableError as exc:
        pytest.skip(f"no OpenGL: {exc}")
    rest = renderer.render("top").astype(float)
    sim.set_tool_target("probe", (0.0, 0.0, 0.018), speed=0.05)
    sim.run(0.4)
    pressed = renderer.render("top").astype(float)
    b = sim.bindings["slab"]
    u = sim.scene.visual.model.flex_texcoord[b.texcoordadr:b.texcoordadr + b.n_vertices, 0]
    assert u.max() > 0.9 and u.min() < 0.02          # yellow under the probe, dark far away
    # the colour change is visible: a ring around the probe (the probe itself hides the centre)
    h, w = rest.shape[:2]
    yy, xx = np.mgrid[:h, :w]
    r = np.hypot(yy - h / 2, xx - w / 2)
    ring = (r > 40) & (r < 70)
    change = np.abs(pressed - rest).sum(axis=2)[ring]
    assert np.mean(change > 60) > 0.2
    # far corners keep the low end of the colour map
    assert np.abs(pressed[5:20, 5:20] - rest[5:20, 5:20]).mean() < 20


def test_unknown_render_field_lists_the_fields():
    from surgsim_envs.scene import build_scene
    from surgsim_envs.scene.builder import palpation_config

    cfg = palpation_config()
    cfg.tissues[0] = dataclasses.replace(cfg.tissues[0], render_field="temperature")
    with pytest.raises(ConfigError, match=r"render_field='temperature'.*\['displacement', 'stress'\]"):
        build_scene(cfg)
