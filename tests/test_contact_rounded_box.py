"""The rounded box of the tissue contact (edges rounded to the thinnest half extent) and the
grasper's ``jaw_edges="round"`` that uses it (surgsim_envs/contact/shapes.py)."""

from __future__ import annotations

import numpy as np
import pytest

from surgsim_envs.contact import BOX, ROUNDED_BOX, ContactModel, ContactParams, signed_distance
from surgsim_envs.contact.shapes import local_outside
from surgsim_envs.errors import ConfigError

from test_contact import POS, ROT, geoms, to_world

SIZE = (0.0015, 0.006, 0.02)        # a grasper jaw: 3 x 12 x 40 mm, edges rounded to 1.5 mm


def sdf(points_local, kind=ROUNDED_BOX, size=SIZE):
    return signed_distance(to_world(points_local), kind, size, POS, ROT.ravel())


def test_rounded_box_distances_match_the_geometry():
    r = min(SIZE)
    hx, hy, hz = (s - r for s in SIZE)                     # the inner box: flat along x
    pts = [[0.004, 0.001, -0.01],                          # over the flat face
           [0.0015 + 1e-3, hy + 1e-3, 0.0],                # outside, off a long edge (45 degrees)
           [0.003, 0.0065, 0.0195],                        # off a corner
           [0.0, 0.0, 0.0],                                # centre
           [0.0005, 0.002, 0.001],                         # inside, nearest the face
           [0.0, 0.0059, 0.0]]                             # inside, on the mid-plane near a long edge
    d, n, c = sdf(pts)
    off_edge = np.hypot(0.0015 + 1e-3, 1e-3) - r
    off_corner = np.linalg.norm([0.003, 0.0065 - hy, 0.0195 - hz]) - r
    expect = [0.004 - 0.0015, off_edge, off_corner, -r, 0.0005 - 0.0015, 0.0059 - hy - r]
    np.testing.assert_allclose(d, expect, atol=1e-15)
    np.testing.assert_allclose(n[0], ROT[:, 0], atol=1e-12)
    np.testing.assert_allclose(n[1], ROT @ (np.array([0.0015 + 1e-3, 1e-3, 0.0]) / np.hypot(0.0015 + 1e-3, 1e-3)),
                               atol=1e-12)
    np.testing.assert_allclose(n[5], ROT[:, 1], atol=1e-12)
    # every closest point lies on the surface, at the signed distance along the normal
    dc, _, _ = signed_distance(c, ROUNDED_BOX, SIZE, POS, ROT.ravel())
    np.testing.assert_allclose(dc, 0.0, atol=1e-15)
    np.testing.assert_allclose(to_world(pts) - c, d[:, None] * n, atol=1e-15)


def test_rounded_box_is_the_box_on_its_flat_faces_and_inside_it_elsewhere():
    rng = np.random.default_rng(3)
    local = rng.uniform(-1.6, 1.6, size=(4000, 3)) * np.asarray(SIZE)
    d_round, _, _ = sdf(local)
    d_box, _, _ = sdf(local, BOX)
    r = min(SIZE)
    inner = np.asarray(SIZE) - r
    over_face = np.sum(np.abs(local) > inner, axis=1) <= 1            # beyond the inner box along one axis at most
    np.testing.assert_allclose(d_round[over_face], d_box[over_face], atol=1e-15)
    assert np.all(d_round >= d_box - 1e-15)                          # the rounded box lies inside the box
    assert np.any(d_round[~over_face] > d_box[~over_face] + 1e-4)     # and departs from it at edges and corners
    # the kernels' cheap rejection stays exact for the rounded box: "outside" only where it is
    outside = np.array([local_outside(ROUNDED_BOX, *SIZE, *q) for q in local])
    assert np.all(d_round[outside] >= 0.0)


def test_node_under_a_rounded_edge_is_pushed_less_and_sideways():
    """Under the face's flat part a rounded jaw presses a node exactly as the box does; under the
    rounded edge the node penetrates less and the force tilts outward."""
    k = 200.0
    x = np.array([[0.0, 0.001, -0.0012], [0.0, 0.005, -0.0012]])    # 0.3 mm into the face at z = -1.5 mm
    mat = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])   # local x -> world -z: face down
    out = {}
    for kind in (BOX, ROUNDED_BOX):
        cm = ContactModel(2, [0, 1], [0.0], ContactParams(stiffness=k, damping=0.0))
        res = cm.compute(x, np.zeros((2, 3)), *geoms([kind], [0], [SIZE], [[0.0, 0.0, 0.0]],
                                                      [mat.ravel()]), np.zeros((1, 3)), 1e-3)
        out[kind] = res.forces.copy()
    np.testing.assert_array_equal(out[BOX][0], out[ROUNDED_BOX][0])
    np.testing.assert_allclose(out[BOX][0], [0.0, 0.0, -k * 0.0003], atol=1e-15)
    np.testing.assert_allclose(out[BOX][1], out[BOX][0], atol=1e-15)
    # 0.5 mm onto the edge's quarter circle (centre at y 4.5 mm, z 0): depth 1.5 - 1.3 mm, normal (0.5, -1.2) / 1.3
    np.testing.assert_allclose(out[ROUNDED_BOX][1], k * 0.0002 * np.array([0.0, 0.5, -1.2]) / 1.3, atol=1e-15)


def _grasp_config(jaw_edges):
    from surgsim_envs.scene.builder import grasp_config

    cfg = grasp_config()
    for tool in cfg.tools:
        if hasattr(tool, "jaw_edges"):
            tool.jaw_edges = jaw_edges
    return cfg


def test_grasper_round_jaw_edges_reach_the_contact_only():
    from surgsim_envs.scene import Simulation
    from surgsim_envs.scene.builder import grasp_scene

    sims = {e: Simulation(grasp_scene(_grasp_config(e))) for e in ("sharp", "round")}
    grasper = next(t for t in sims["round"].tools.values() if t.jaw_geoms)
    rows = sims["round"].geom_rows(grasper.jaw_geom_ids)
    kinds = {e: s.shape_kinds for e, s in sims.items()}
    assert np.all(kinds["round"][rows] == ROUNDED_BOX) and np.all(kinds["sharp"][rows] == BOX)
    others = np.setdiff1d(np.arange(len(kinds["round"])), rows)
    np.testing.assert_array_equal(kinds["round"][others], kinds["sharp"][others])
    # MuJoCo keeps the box (rendering, rigid collisions)
    np.testing.assert_array_equal(sims["round"].model.geom_type, sims["sharp"].model.geom_type)
    with pytest.raises(ConfigError, match="jaw_edges='rounded'.*'sharp'.*'round'"):
        grasp_scene(_grasp_config("rounded"))


def test_batched_backend_refuses_round_jaw_edges():
    from surgsim_envs.batch import backend

    if not backend.available():
        pytest.skip("the batched backend's packages are missing (pip install -e '.[batch]')")
    from surgsim_envs.batch.simulation import BatchSimulation
    from surgsim_envs.scene import Simulation
    from surgsim_envs.scene.builder import grasp_scene

    with pytest.raises(backend.BatchUnavailableError, match="jaw_edges='round'"):
        BatchSimulation(Simulation(grasp_scene(_grasp_config("round"))), 2, device="cpu")


def test_grasp_reference_takes_the_jaw_edges_and_its_column_cache():
    from surgsim_envs.bench import grasp_reference as ref
    from surgsim_envs.bench.probe_sets import slippage_pull as sp

    env = sp.make_env(ref.REFERENCE_MODEL, None, sp.CLOSURE)
    try:
        kinds = {e: ref.reference_simulation(env, 0.015, e).shape_kinds for e in (None, "round")}
        caches = [ref.reference_simulation(env, 0.015, cache_mb=c).tissue().cache_mb for c in (None, 2500.0)]
    finally:
        env.close()
    assert caches == [ref.REFERENCE_OPTIONS["cache_mb"], 2500.0]
    assert ROUNDED_BOX not in kinds[None]                       # the task's jaws: sharp
    assert np.sum(kinds["round"] == ROUNDED_BOX) == 3           # the three jaws, not the shaft


@pytest.mark.parametrize("task", ["SurgSim/Grasp-v0", "SurgSim/Slippage-v0"])
def test_grasp_tasks_take_round_jaw_edges(task):
    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401  (registers the tasks)

    env = gym.make(task, jaw_edges="round")
    try:
        env.reset(seed=0)
        obs, *_ = env.step(env.action_space.sample())
        assert np.all(np.isfinite(obs))
        assert np.sum(env.unwrapped.sim.shape_kinds == ROUNDED_BOX) == 3
    finally:
        env.close()
    with pytest.raises(ConfigError, match="jaw_edges='rounded'; choose 'sharp'"):
        gym.make(task, jaw_edges="rounded")
