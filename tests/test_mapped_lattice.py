"""Lattice tets on a graded tensor grid (geometry/mapped_lattice.py) and the grasp reference's
tip-graded organ (bench/grasp_tip_lattice.py)."""

import numpy as np
import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry import lattice_volume, spleen_surface, surface_distance, tet_signed_volumes
from surgsim_envs.geometry.graded_axis import graded_axis
from surgsim_envs.geometry.mapped_lattice import from_grid, mapped_lattice_volume, to_grid

FINE, COARSE = 0.003, 0.009


@pytest.fixture(scope="module")
def spleen():
    return spleen_surface()


def _graded_axes(surface):
    lo, hi = surface.bounds
    x = graded_axis(lo[0] - 0.03, hi[0] + 0.03, hi[0] - 0.02, 0.025, FINE, COARSE, 1.3)
    y, z = (lo[k] - 0.01 + FINE * np.arange(int((hi[k] - lo[k] + 0.02) / FINE) + 1) for k in (1, 2))
    return x, y, z


def test_grid_map_round_trips_inside_and_beyond_the_axis():
    coords = np.array([0.0, 0.001, 0.003, 0.007, 0.015])
    x = np.array([-0.002, 0.0, 0.0005, 0.002, 0.006, 0.015, 0.031])
    xi = to_grid(x, coords)
    np.testing.assert_allclose(xi, [-2.0, 0.0, 0.5, 1.5, 2.75, 4.0, 6.0])
    np.testing.assert_allclose(from_grid(xi, coords), x, atol=1e-15)


def test_uniform_axes_give_the_uniform_lattice(spleen):
    h = 0.0055
    lo, hi = spleen.bounds
    axes = [lo[k] - 3 * h + h * np.arange(int((hi[k] - lo[k]) / h) + 7) for k in range(3)]
    mapped = mapped_lattice_volume(spleen, axes)
    uniform = lattice_volume(spleen, h)
    assert mapped.n_nodes == uniform.n_nodes and len(mapped.tets) == len(uniform.tets)
    v_m, v_u = (tet_signed_volumes(v.nodes, v.tets).sum() for v in (mapped, uniform))
    assert abs(v_m / v_u - 1.0) < 1e-4


def test_graded_lattice_is_fine_at_the_tip_coarse_elsewhere_and_on_the_surface(spleen):
    vol = mapped_lattice_volume(spleen, _graded_axes(spleen))
    lo, hi = spleen.bounds
    assert np.all(tet_signed_volumes(vol.nodes, vol.tets) > 0.0)
    assert vol.n_nodes < 0.7 * lattice_volume(spleen, FINE).n_nodes      # fine over 45 of 115 mm
    interior = np.setdiff1d(np.arange(vol.n_nodes), vol.surface_nodes)
    planes = np.unique(np.round(vol.nodes[interior, 0], 9))
    gaps = np.diff(planes)
    tip = planes[1:] > hi[0] - 0.015
    np.testing.assert_allclose(gaps[tip], FINE, rtol=1e-6)          # fine cells where the load goes
    assert gaps.max() > 2.5 * FINE                                   # coarse along the rest
    # boundary nodes snap at most half their local cell, as on the uniform lattice (largest cell side)
    dist = surface_distance(vol, spleen)
    x = vol.nodes[vol.surface_nodes, 0]
    assert dist[x > hi[0] - 0.015].max() <= 0.5 * FINE * np.sqrt(3)
    assert dist.max() <= 0.5 * COARSE
    enclosed = tet_signed_volumes(vol.nodes, vol.tets).sum()
    assert abs(enclosed / spleen.volume - 1.0) < 0.02


def test_bad_axes_are_refused_by_name(spleen):
    x, y, z = _graded_axes(spleen)
    with pytest.raises(ConfigError, match="y axis must be >= 4 finite, strictly ascending"):
        mapped_lattice_volume(spleen, (x, y[::-1], z))
    with pytest.raises(ConfigError, match="x axis .* must reach 2 cells beyond the surface"):
        mapped_lattice_volume(spleen, (x[x < 0.0], y, z))
    with pytest.raises(ConfigError, match="three coordinate arrays"):
        mapped_lattice_volume(spleen, (x, y))


@pytest.mark.slow
def test_tip_graded_organ_fills_the_task_surface_and_the_reference_places_it_there(monkeypatch):
    import trimesh

    from surgsim_envs.bench import grasp_reference as ref
    from surgsim_envs.bench import grasp_tip_lattice
    from surgsim_envs.bench.grasp_tip_lattice import tip_graded_volume
    from surgsim_envs.bench.probe_sets import grasp_closure as gc
    from surgsim_envs.scene.builder import placed_volume

    fine, coarse = 0.004, 0.008
    monkeypatch.setattr(grasp_tip_lattice, "TIP_COARSE_SPACING", coarse)   # a small lattice for the test
    env = gc.make_env(ref.REFERENCE_MODEL, None)
    try:
        tissue = env.sim.scene.config.tissues[0]
        vol = tip_graded_volume(tissue, fine, 0.02)
        placed = ref.reference_simulation(env, fine, graded_tip=0.02)
        with pytest.raises(ConfigError, match="length 0.5 m must be in"):
            tip_graded_volume(tissue, fine, 0.5)
        with pytest.raises(ConfigError, match="must be > 0 and <= the coarse"):
            tip_graded_volume(tissue, 0.004, 0.03, coarse=0.003)
        task_surface = trimesh.Trimesh(*placed_volume(tissue).source_surface, process=False)
    finally:
        env.close()
    x = vol.nodes
    assert len(x) < 0.75 * lattice_volume(task_surface, fine).n_nodes   # fine over the last 20 mm + a margin
    # filled into the task's placed organ surface: boundary nodes within half a cell of it
    _, dist, _ = task_surface.nearest.on_surface(x[vol.surface_nodes])
    assert dist.max() <= 0.5 * np.sqrt(3) * coarse
    interior = np.setdiff1d(np.arange(len(x)), vol.surface_nodes)
    tip = x[:, 0].max()
    planes = np.unique(np.round(x[interior][x[interior, 0] > tip - 0.015, 0], 9))
    np.testing.assert_allclose(np.diff(planes), fine, rtol=1e-6)   # the spacing where the jaws grasp
    assert np.diff(np.unique(np.round(x[interior, 0], 9))).max() > 1.5 * fine
    # reference_simulation(graded_tip=...) puts the graded organ where it was filled
    np.testing.assert_allclose(placed.tissue().rest_positions, x, rtol=0, atol=1e-12)
