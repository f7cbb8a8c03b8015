"""Contact on the tissue surface between the nodes (embedded barycentric contact samples)."""

from __future__ import annotations

import numpy as np
import pytest

from surgsim_envs.contact import BOX, CAPSULE, SPHERE, ContactModel, ContactParams
from surgsim_envs.contact.surface_points import (typical_edge_length, subdivisions_for_spacing,
                                                 surface_samples)
from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry import box_volume

H = 0.01          # m, coarse lattice spacing
TIP = 0.003       # m, probe tip radius (smaller than the lattice)
K = 200.0         # N/m per node


@pytest.fixture(scope="module")
def slab():
    return box_volume((0.06, 0.06, 0.02), H)


def press(cm, x, centre, r=TIP):
    cm.reset()
    return cm.compute(x, np.zeros_like(x), [SPHERE], [0], [[r, 0, 0]], [centre], [np.eye(3).ravel()],
                      np.zeros((1, 6)), np.zeros((1, 3)), 1e-3)


def continuum_force(centre, depth_top, r, stiffness_per_area, z_top):
    """z force of a sphere on a rigid plane z = z_top with penalty stiffness per area: quadrature."""
    s = np.linspace(-r, r, 801)
    gx, gy = np.meshgrid(s, s)
    dist = np.sqrt(gx ** 2 + gy ** 2 + (centre[2] - z_top) ** 2)
    depth = np.maximum(r - dist, 0.0)
    fz = -stiffness_per_area * depth * (centre[2] - z_top) / dist
    return fz.sum() * (s[1] - s[0]) ** 2


def test_sample_layout_counts_and_weights(slab):
    tri = slab.surface
    for n in (1, 2, 3, 5):
        nodes, w = surface_samples(tri, n)
        edges = np.unique(np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1), axis=0)
        assert len(nodes) == len(edges) * (n - 1) + len(tri) * (n - 1) * (n - 2) // 2
        assert np.allclose(w.sum(axis=1), 1.0) and np.all(w >= 0) and np.all(w < 1.0)
        # a closed genus-0 surface (E = 3V - 6, F = 2V - 4) has n^2 (V - 2) + 2 contact points:
        # n^2 per vertex up to a constant
        v = len(np.unique(tri))
        assert v + len(nodes) == n * n * (v - 2) + 2
        # no duplicated sample positions
        pts = np.einsum("sj,sjk->sk", w, slab.nodes[nodes])
        if len(pts):
            assert len(np.unique(np.round(pts / 1e-9).astype(np.int64), axis=0)) == len(pts)
    assert subdivisions_for_spacing(slab.nodes, tri, TIP) == int(np.ceil(typical_edge_length(slab.nodes, tri) / TIP))
    with pytest.raises(ConfigError, match="subdivisions"):
        surface_samples(tri, 0)
    with pytest.raises(ConfigError, match="sample_spacing"):
        subdivisions_for_spacing(slab.nodes, tri, -1.0)


def test_small_tip_between_nodes_feels_force_like_at_a_node(slab):
    """A tip smaller than the lattice: node-only contact feels nothing between four nodes; with
    surface samples it feels about what it feels on a node, rising with depth, and close to a
    continuum penalty with the same stiffness per area (k_n / h^2)."""
    x = slab.nodes
    top = x[:, 2].max()
    nodes_only = ContactModel(slab.n_nodes, slab.surface_nodes, [0.5], ContactParams(stiffness=K, damping=0.0))
    cm = ContactModel(slab.n_nodes, slab.surface_nodes, [0.5], ContactParams(stiffness=K, damping=0.0),
                      surface=slab.surface, sample_spacing=TIP / 2, rest_positions=x)
    assert cm.surface_subdivisions >= 2 and cm.n_samples > 0
    between, at_node = (0.0033, 0.0061), (0.0, 0.0)  # (0, 0) is a lattice node
    prev = 0.0
    for depth in (0.0008, 0.0012, 0.0016, 0.002):
        z = top + TIP - depth
        assert np.all(press(nodes_only, x, (*between, z)).forces == 0.0)  # the tip falls between the nodes
        f_between = -press(cm, x, (*between, z)).forces.sum(axis=0)[2]
        f_node = -press(cm, x, (*at_node, z)).forces.sum(axis=0)[2]
        assert f_between > prev
        prev = f_between
        assert f_between == pytest.approx(f_node, rel=0.2)
        expected = continuum_force((0.0, 0.0, z), depth, TIP, K / H ** 2, top)
        assert -expected == pytest.approx(f_between, rel=0.25)


def test_broad_indenter_force_unchanged_by_sampling(slab):
    """Per-point stiffness k_n / n^2: a flat box much larger than the lattice pressed into the
    top face feels (nearly) the same force with and without samples."""
    x = slab.nodes
    top = x[:, 2].max()
    depth = 0.0005
    half = 0.0235  # m, box half-width: a 4.7 cm square patch, edges off the lattice lines
    g = ([BOX], [0], [[half, half, 0.005]], [[0.0, 0.0, top + 0.005 - depth]], [np.eye(3).ravel()],
         np.zeros((1, 6)), np.zeros((1, 3)), 1e-3)
    continuum = K / H ** 2 * (2 * half) ** 2 * depth   # stiffness per area x area x depth
    for n in (1, 2, 3, 4):
        cm = ContactModel(slab.n_nodes, slab.surface_nodes, [0.5], ContactParams(stiffness=K, damping=0.0),
                          surface=slab.surface, surface_subdivisions=n)
        res = cm.compute(x, np.zeros_like(x), *g)
        # stiffness per node: sum of w k over contact points; total = k/n^2 per point in contact
        assert res.stiffness.sum() == pytest.approx(K / n ** 2 * res.report.contacts[0], rel=1e-12)
        assert res.report.contacts[0] > (2 * half * n / H - 2) ** 2
        assert -res.forces.sum(axis=0)[2] == pytest.approx(continuum, rel=0.2)


def test_sample_forces_conserve_momentum_and_angular_momentum(slab):
    """Random deformation + moving tools, friction stretched: the node forces plus the tool
    reactions sum to zero, and so do their torques (reaction applied at the sample point)."""
    rng = np.random.default_rng(7)
    x0 = slab.nodes.copy()
    top = x0[:, 2].max()
    v = rng.normal(scale=0.02, size=x0.shape)
    kinds = [SPHERE, CAPSULE, BOX]
    size = np.array([[TIP, 0, 0], [0.002, 0.01, 0], [0.004, 0.006, 0.003]])
    pos = np.array([[0.004, 0.003, top + TIP - 0.001], [-0.012, 0.007, top + 0.0015], [0.015, -0.01, top + 0.002]])
    ang = 0.7
    rot = np.array([[np.cos(ang), -np.sin(ang), 0], [np.sin(ang), np.cos(ang), 0], [0, 0, 1]])
    mats = np.stack([np.eye(3).ravel(), np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float).ravel(), rot.ravel()])
    com = rng.uniform(-0.03, 0.03, size=(2, 3))
    cm = ContactModel(slab.n_nodes, slab.surface_nodes, [0.3, 0.8], ContactParams(stiffness=K, damping=0.3),
                      surface=slab.surface, surface_subdivisions=4)
    x = x0
    for step in range(6):
        x = x0 + rng.normal(scale=2e-4, size=x0.shape) + np.array([1e-4 * step, 0, 0])
        res = cm.compute(x, v, kinds, [0, 1, 1], size, pos, mats, np.zeros((3, 6)), com, 1e-3)
    assert res.report.contacts.sum() > 10 and res.report.slipping.sum() > 0
    scale = np.abs(res.forces).sum()
    assert scale > 0
    total = res.forces.sum(axis=0) + res.tool_force.sum(axis=0)
    assert np.linalg.norm(total) <= 1e-12 * scale
    torque = np.cross(x, res.forces).sum(axis=0) + (res.tool_torque + np.cross(com, res.tool_force)).sum(axis=0)
    assert np.linalg.norm(torque) <= 1e-12 * scale * 0.1
    # contact counts are contact points with negative signed distance
    from surgsim_envs.contact import signed_distance

    pts = np.concatenate([x[cm.candidate_nodes], cm.sample_positions(x)])
    inside = np.zeros(len(pts), dtype=bool)
    for g in range(3):
        d, _, _ = signed_distance(pts, kinds[g], size[g], pos[g], mats[g])
        assert np.array_equal(cm.points_in_contact[:, g], d < 0)
        inside |= d < 0
    assert cm.in_contact.shape == (len(cm.candidate_nodes), 3)


def test_single_sample_force_is_split_by_barycentric_weights():
    """One triangle, one interior sample (n = 3) pressed by a small sphere: each node gets
    w_j times the sample force, and w_j k_n / n^2 of stiffness."""
    x = np.array([[0.0, 0.0, 0.0], [0.03, 0.0, 0.0], [0.0, 0.03, 0.0]])
    tri = np.array([[0, 1, 2]])
    cm = ContactModel(3, [0, 1, 2], [0.0], ContactParams(stiffness=K, damping=0.0), surface=tri,
                      surface_subdivisions=3)
    nodes, w = cm.sample_nodes, cm.sample_weights
    interior = np.flatnonzero(np.all(w > 0, axis=1))
    assert len(interior) == 1
    s = interior[0]
    xs = w[s] @ x[nodes[s]]
    r, depth = 0.002, 0.0005
    res = press(cm, x, xs + [0, 0, r - depth], r=r)
    f = K / 9 * depth * np.array([0, 0, -1.0])
    expected = np.zeros((3, 3))
    for j in range(3):
        expected[nodes[s, j]] += w[s, j] * f
    np.testing.assert_allclose(res.forces, expected, atol=1e-15)
    np.testing.assert_allclose(res.forces.sum(axis=0), f, atol=1e-15)
    exp_k = np.zeros(3)
    np.add.at(exp_k, nodes[s], w[s] * K / 9)
    np.testing.assert_allclose(res.stiffness, exp_k, rtol=1e-12)
    assert res.report.contacts[0] == 1 and res.report.penetration[0] == pytest.approx(depth)


def test_surface_option_errors():
    with pytest.raises(ConfigError, match="surface"):
        ContactModel(3, [0], [0.5], surface_subdivisions=2)
    with pytest.raises(ConfigError, match="rest_positions"):
        ContactModel(3, [0], [0.5], surface=[[0, 1, 2]], sample_spacing=0.002)
    with pytest.raises(ConfigError, match="either"):
        ContactModel(3, [0], [0.5], surface=[[0, 1, 2]], sample_spacing=0.002, surface_subdivisions=2,
                     rest_positions=np.eye(3))
    with pytest.raises(ConfigError, match=r"\[0, 3\)"):
        ContactModel(3, [0], [0.5], surface=[[0, 1, 5]], surface_subdivisions=2)


def test_scene_probe_smaller_than_lattice_feels_the_surface():
    """Simulation wiring: ContactConfig.surface_samples="auto" turns samples on for a 3 mm tip on a
    10 mm lattice; the tip pressed between four nodes then pushes the tissue (and feels it), while
    nodes-only contact lets it sink in without any force."""
    from surgsim_envs.scene import ProbeConfig, SceneConfig, Simulation, TissueConfig, build_scene
    from surgsim_envs.scene.config import ContactConfig

    def run(samples):
        tissue = TissueConfig(name="slab", organ="slab", spacing=H, anchors=("bottom",), position=(0.0, 0.0, 0.01),
                              volume_options={"size": (0.06, 0.06, 0.02)}, options={"integrator": "symplectic"})
        probe = ProbeConfig(name="probe", tip_radius=TIP, position=(0.005, 0.005, 0.02 + TIP + 0.002))
        sim = Simulation(build_scene(SceneConfig(name="small_tip", tissues=[tissue], tools=[probe], dt=5e-4,
                                                 contact=ContactConfig(surface_samples=samples))))
        sim.set_tool_target("probe", [0.005, 0.005, 0.02 + TIP - 0.002], speed=0.05)
        sim.run(0.15)
        return sim, sim.contact_report()["probe"], sim.tool_force("probe")

    sim, rep, force = run("auto")
    cm = sim.contacts["slab"]
    assert cm.surface_subdivisions == int(np.ceil(H / TIP)) and cm.n_samples > 0
    assert rep["contacts"] > 0 and rep["normal_force"] > 0 and force[2] > 0   # the tissue pushes the tip up
    rest = sim.tissue().rest_positions
    upper = np.flatnonzero(rest[:, 2] > rest[:, 2].max() - 1e-9)
    assert sim.tissue().positions[upper, 2].min() < rest[:, 2].max() - 1e-4   # the upper face is dented
    sim, rep, force = run(None)
    assert sim.contacts["slab"].n_samples == 0
    assert rep["contacts"] == 0 and np.all(force == 0.0)
    with pytest.raises(ConfigError, match="surface_samples"):
        run(99)
