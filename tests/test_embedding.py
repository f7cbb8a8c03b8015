"""A smooth visual surface embedded in the lattice tets follows the tissue (geometry/embedding.py)."""

from __future__ import annotations

import numpy as np
import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry import box_volume, embed_points, interpolate, make_volume


@pytest.fixture(scope="module")
def spleen():
    vol = make_volume("spleen", spacing=0.008)
    return vol, vol.source_surface


def test_procedural_organ_keeps_its_smooth_surface(spleen):
    vol, (verts, faces) = spleen
    assert verts.shape[1] == 3 and faces.shape[1] == 3 and faces.max() < len(verts)
    # the smooth surface and the snapped lattice agree to within a lattice spacing
    lo, hi = vol.bounds()
    assert np.all(verts.min(axis=0) > lo - 0.008) and np.all(verts.max(axis=0) < hi + 0.008)


def test_rest_reproduces_the_vertices_exactly(spleen):
    vol, (verts, _) = spleen
    emb = embed_points(verts, vol.nodes, vol.tets)
    assert not emb.clamped.any()
    assert emb.inside.any() and (~emb.inside).any()     # both contained and extrapolated vertices
    np.testing.assert_allclose(emb.weights.sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(emb.positions(vol.nodes), verts, atol=1e-12)
    # contained vertices have non-negative weights
    assert emb.weights[emb.inside].min() >= -1e-9


def test_affine_deformation_is_reproduced_exactly(spleen):
    vol, (verts, _) = spleen
    emb = embed_points(verts, vol.nodes, vol.tets)
    rng = np.random.default_rng(1)
    a = np.eye(3) + rng.normal(scale=0.2, size=(3, 3))
    b = rng.normal(scale=0.01, size=3)
    out = np.empty((len(verts), 3))
    interpolate(vol.nodes @ a.T + b, emb.tet_nodes, emb.weights, out)
    np.testing.assert_allclose(out, verts @ a.T + b, atol=1e-12)


def test_nonaffine_deformation_moves_vertex_with_its_tet():
    """A vertex inside a tet follows only that tet's nodes; far outside points are clamped."""
    vol = box_volume((0.02, 0.02, 0.02), 0.01)
    pts = np.array([[0.001, 0.002, 0.003], [0.5, 0.5, 0.5]])
    emb = embed_points(pts, vol.nodes, vol.tets, max_extrapolation=1.0)
    assert emb.inside[0] and not emb.inside[1] and emb.clamped[1] and not emb.clamped[0]
    x = vol.nodes.copy()
    others = np.setdiff1d(np.arange(vol.n_nodes), emb.tet_nodes[0])
    x[others] += 0.005                                   # move every node not of the vertex's tet
    assert np.allclose(emb.positions(x)[0], pts[0], atol=1e-15)
    assert np.all(np.abs(emb.weights[1]) <= 2.0 + 1e-12) and emb.weights[1].sum() == pytest.approx(1.0)


def test_bad_inputs():
    vol = box_volume((0.02, 0.02, 0.02), 0.01)
    with pytest.raises(ConfigError, match="points"):
        embed_points(np.zeros((0, 3)), vol.nodes, vol.tets)
    with pytest.raises(ConfigError, match="tets"):
        embed_points(np.zeros((1, 3)), vol.nodes, np.zeros((0, 4), int))
    with pytest.raises(ConfigError, match="max_extrapolation"):
        embed_points(np.zeros((1, 3)), vol.nodes, vol.tets, max_extrapolation=-1)


def test_scene_renders_the_smooth_embedded_surface():
    """The grasp scene's spleen flex is the smooth surface; sync_visual writes the interpolated
    vertices, which move with the tissue."""
    from surgsim_envs.scene import Simulation
    from surgsim_envs.scene.builder import grasp_config, grasp_scene
    from surgsim_envs.scene.tissue_binding import TissueBinding

    cfg = grasp_config()
    cfg.tissues[0].spacing = 0.01
    sim = Simulation(grasp_scene(cfg))
    binding = sim.bindings["spleen"]
    assert binding.smooth
    verts = sim.tissue().volume.source_surface[0]
    nodes = sim.tissue().rest_positions                  # the surface was placed like the nodes
    assert np.all(np.abs(verts.min(axis=0) - nodes.min(axis=0)) < 0.01)
    assert np.all(np.abs(verts.max(axis=0) - nodes.max(axis=0)) < 0.01)
    sim.sync_visual()
    flex = sim.render_data.flexvert_xpos[binding.vertadr:binding.vertadr + binding.n_vertices]
    np.testing.assert_allclose(flex, verts, atol=1e-12)
    tissue = sim.tissue()
    tissue.positions[:] = tissue.rest_positions + [0.0, 0.0, 0.003]
    sim.sync_visual()
    flex = sim.render_data.flexvert_xpos[binding.vertadr:binding.vertadr + binding.n_vertices]
    np.testing.assert_allclose(flex, verts + [0.0, 0.0, 0.003], atol=1e-12)
    tissue.positions[:] = tissue.rest_positions
    lattice = TissueBinding("x", tissue, visual="lattice")
    assert not lattice.smooth and lattice.n_vertices == len(tissue.surface_nodes)
    with pytest.raises(ConfigError, match="visual"):
        TissueBinding("x", tissue, visual="shiny")
