"""Tool-tissue contact: shape signed distances, penalty normal force, no adhesion, action = reaction,
Coulomb stick/slip friction (surgsim_envs.contact)."""

from __future__ import annotations

import numpy as np
import pytest

from surgsim_envs.contact import (BOX, CAPSULE, CYLINDER, SPHERE, ContactModel, ContactParams,
                                  auto_stiffness, signed_distance)
from surgsim_envs.errors import ConfigError


def rotation(axis, angle) -> np.ndarray:
    """Rodrigues rotation matrix (3,3)."""
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


ROT = rotation([1.0, 2.0, -0.5], 0.7)
POS = np.array([0.01, -0.02, 0.03])


def to_world(local):
    return POS + np.asarray(local, float) @ ROT.T


def sdf(points_local, kind, size):
    """signed_distance of points given in the shape's local frame (posed with ROT, POS)."""
    return signed_distance(to_world(points_local), kind, size, POS, ROT.ravel())


# ---------------------------------------------------------------------------------------------
# Signed distances against analytic formulas (rotated, translated frames)
def test_sphere_sdf_matches_formula():
    rng = np.random.default_rng(0)
    r = 0.01
    local = rng.normal(size=(200, 3)) * 0.01
    d, n, c = sdf(local, SPHERE, (r, 0, 0))
    rad = np.linalg.norm(local, axis=1)
    np.testing.assert_allclose(d, rad - r, atol=1e-14)
    np.testing.assert_allclose(n, (local / rad[:, None]) @ ROT.T, atol=1e-12)
    np.testing.assert_allclose(c, to_world(r * local / rad[:, None]), atol=1e-14)
    # on the surface
    d, _, _ = sdf([[r, 0, 0], [0, 0, -r]], SPHERE, (r, 0, 0))
    np.testing.assert_allclose(d, 0.0, atol=1e-15)


def test_capsule_sdf_is_distance_to_segment_minus_radius():
    rng = np.random.default_rng(1)
    r, h = 0.004, 0.01
    local = rng.uniform(-0.02, 0.02, size=(300, 3))
    d, n, c = sdf(local, CAPSULE, (r, h, 0))
    s = np.clip(local[:, 2], -h, h)
    seg = np.stack([np.zeros_like(s), np.zeros_like(s), s], axis=1)
    expect = np.linalg.norm(local - seg, axis=1) - r
    np.testing.assert_allclose(d, expect, atol=1e-14)
    # closest point lies on the capsule surface and x = closest + d * n
    np.testing.assert_allclose(to_world(local), c + d[:, None] * n, atol=1e-14)
    # hand-picked: beside the middle, beyond the cap, inside
    d, _, _ = sdf([[0.01, 0, 0.003], [0, 0, h + r + 0.002], [0.001, 0, 0]], CAPSULE, (r, h, 0))
    np.testing.assert_allclose(d, [0.01 - r, 0.002, 0.001 - r], atol=1e-15)


def test_box_sdf_inside_outside_edges_corners():
    hx, hy, hz = 0.01, 0.02, 0.005
    pts = [
        [hx + 0.003, 0.0, 0.0],                 # outside a face
        [0.0, -hy - 0.001, 0.0],
        [hx + 0.003, hy + 0.004, 0.0],          # outside an edge
        [-hx - 0.001, hy + 0.002, -hz - 0.002],  # outside a corner
        [0.0, 0.0, 0.0],                        # centre: nearest face is z (hz smallest)
        [hx - 0.002, 0.0, 0.0],                 # inside, nearest face +x
        [0.0, 0.0, -hz],                        # on the surface
    ]
    d, n, c = sdf(pts, BOX, (hx, hy, hz))
    expect = [0.003, 0.001, 0.005, np.sqrt(0.001**2 + 0.002**2 + 0.002**2), -hz, -0.002, 0.0]
    np.testing.assert_allclose(d, expect, atol=1e-15)
    np.testing.assert_allclose(n[0], ROT[:, 0], atol=1e-12)
    np.testing.assert_allclose(n[5], ROT[:, 0], atol=1e-12)
    np.testing.assert_allclose(n[4], ROT[:, 2] * np.sign(n[4] @ ROT[:, 2]), atol=1e-12)
    np.testing.assert_allclose(c[2], to_world([hx, hy, 0.0]), atol=1e-14)
    np.testing.assert_allclose(c[5], to_world([hx, 0.0, 0.0]), atol=1e-14)


def test_cylinder_sdf_side_cap_rim_inside():
    r, h = 0.005, 0.01
    pts = [
        [0.008, 0.0, 0.002],          # beside: radial distance
        [0.0, 0.003, h + 0.004],      # above the cap
        [0.006, 0.0, -h - 0.002],     # beyond the rim (edge circle)
        [0.0, 0.004, 0.0],            # inside, nearer the side (1 mm) than the caps (10 mm)
        [0.0, 0.0, -h + 0.0005],      # inside, nearer the bottom cap
        [0.003, 0.004, 0.0],          # on the side surface
    ]
    d, n, c = sdf(pts, CYLINDER, (r, h, 0))
    expect = [0.003, 0.004, np.hypot(0.001, 0.002), -0.001, -0.0005, 0.0]
    np.testing.assert_allclose(d, expect, atol=1e-15)
    np.testing.assert_allclose(n[1], ROT[:, 2], atol=1e-12)
    np.testing.assert_allclose(n[3], ROT[:, 1], atol=1e-12)
    np.testing.assert_allclose(n[4], -ROT[:, 2], atol=1e-12)
    np.testing.assert_allclose(c[2], to_world([r, 0.0, -h]), atol=1e-14)


@pytest.mark.parametrize("kind,size", [(SPHERE, (0.01, 0, 0)), (CAPSULE, (0.004, 0.01, 0)),
                                       (BOX, (0.01, 0.006, 0.004)), (CYLINDER, (0.006, 0.008, 0))])
def test_sdf_agrees_with_brute_force_surface_sampling(kind, size):
    """|d| equals the distance to a dense point sampling of the surface; sign from membership."""
    rng = np.random.default_rng(2)
    # dense surface samples: project random points onto the surface with the closest-point map
    seeds = rng.uniform(-0.02, 0.02, size=(60_000, 3))
    _, _, surf = sdf(seeds, kind, size)
    local = rng.uniform(-0.02, 0.02, size=(300, 3))
    d, _, _ = sdf(local, kind, size)
    world = to_world(local)
    nearest = np.array([np.min(np.linalg.norm(surf - p, axis=1)) for p in world])
    np.testing.assert_allclose(np.abs(d), nearest, atol=1.5e-3)
    # membership from the analytic definitions
    r = size[0]
    if kind == SPHERE:
        inside = np.linalg.norm(local, axis=1) < r
    elif kind == CAPSULE:
        s = np.clip(local[:, 2], -size[1], size[1])
        inside = np.hypot(np.hypot(local[:, 0], local[:, 1]), local[:, 2] - s) < r
    elif kind == BOX:
        inside = np.all(np.abs(local) < np.asarray(size), axis=1)
    else:
        inside = (np.hypot(local[:, 0], local[:, 1]) < r) & (np.abs(local[:, 2]) < size[1])
    assert np.array_equal(d < 0, inside)


def test_sdf_rejects_bad_shapes():
    with pytest.raises(ConfigError, match="shape kind"):
        signed_distance(np.zeros((1, 3)), 7, (0.01, 0, 0))
    with pytest.raises(ConfigError, match="positive"):
        signed_distance(np.zeros((1, 3)), BOX, (0.01, 0.0, 0.01))
    with pytest.raises(ConfigError, match="orthonormal"):
        signed_distance(np.zeros((1, 3)), SPHERE, (0.01, 0, 0), mat=2 * np.eye(3))


# ---------------------------------------------------------------------------------------------
# Normal force
def geoms(kinds, tools, sizes, poss, mats=None, vels=None):
    g = len(kinds)
    mats = np.tile(np.eye(3).ravel(), (g, 1)) if mats is None else np.asarray(mats, float).reshape(g, 9)
    vels = np.zeros((g, 6)) if vels is None else np.asarray(vels, float).reshape(g, 6)
    return (np.asarray(kinds), np.asarray(tools), np.asarray(sizes, float).reshape(g, 3),
            np.asarray(poss, float).reshape(g, 3), mats, vels)


def test_pressed_node_gets_k_times_depth_along_normal():
    k = 250.0
    cm = ContactModel(3, [0, 2], [0.5], ContactParams(stiffness=k, damping=0.0))
    r = 0.01
    centre = np.array([0.0, 0.0, 0.0])
    direction = np.array([1.0, -2.0, 2.0]) / 3.0
    depth = 0.0013
    x = np.zeros((3, 3))
    x[0] = centre + (r - depth) * direction
    x[1] = centre + 0.5 * r * direction           # inside but not a candidate: no force
    x[2] = centre + (r + 0.001) * direction       # outside
    res = cm.compute(x, np.zeros((3, 3)), *geoms([SPHERE], [0], [(r, 0, 0)], [centre]), np.zeros((1, 3)), 1e-3)
    np.testing.assert_allclose(res.forces[0], k * depth * direction, rtol=1e-12)
    assert np.all(res.forces[1:] == 0.0)
    assert res.stiffness[0] == pytest.approx(k) and res.stiffness[2] == 0.0
    assert res.report.contacts[0] == 1 and res.report.slipping[0] == 0
    assert res.report.penetration[0] == pytest.approx(depth, rel=1e-9)
    assert res.report.normal_force[0] == pytest.approx(k * depth, rel=1e-12)
    assert res.geom_normal_force[0] == pytest.approx(k * depth, rel=1e-12)


def test_damping_only_while_approaching_and_never_adhesive():
    k, c = 200.0, 0.8
    cm = ContactModel(1, [0], [0.0], ContactParams(stiffness=k, damping=c))
    depth = 0.0005
    x = np.array([[0.0, 0.0, 0.01 - depth]])     # inside the top of a sphere at the origin, normal +z
    g = geoms([SPHERE], [0], [(0.01, 0, 0)], [(0, 0, 0)])
    com = np.zeros((1, 3))

    def fz(v_node, v_geom=np.zeros(6)):
        cm.reset()
        gg = g[:5] + (np.asarray(v_geom, float).reshape(1, 6),)
        return cm.compute(x, np.asarray(v_node, float).reshape(1, 3), *gg, com, 1e-3).forces[0, 2]

    assert fz([0, 0, -0.1]) == pytest.approx(k * depth + c * 0.1)       # approaching: damped
    assert fz([0, 0, +0.1]) == pytest.approx(k * depth)                 # separating: no pull
    assert fz([0, 0, +50.0]) >= 0.0                                      # never adhesive
    # relative velocity uses the geom's motion: the sphere moving up into a resting node
    assert fz([0, 0, 0], [0, 0, 0, 0, 0, 0.1]) == pytest.approx(k * depth + c * 0.1)
    # ... and a rotating geom: w x (x - p) at the node; w about x gives -y motion, tangential only
    assert fz([0, 0, 0], [3.0, 0, 0, 0, 0, 0]) == pytest.approx(k * depth)
    # separated node: nothing
    cm.reset()
    res = cm.compute(x + [0, 0, 2 * depth], np.zeros((1, 3)), *g, com, 1e-3)
    assert np.all(res.forces == 0.0) and res.report.contacts[0] == 0


def test_newtons_third_law_forces_and_torques():
    """Sum of node forces + tool forces = 0; node torques + tool torques (about tool_com) = 0."""
    rng = np.random.default_rng(3)
    n = 400
    x = rng.uniform(-0.03, 0.03, size=(n, 3))
    v = rng.normal(scale=0.05, size=(n, 3))
    g = geoms([SPHERE, CAPSULE, BOX, CYLINDER], [0, 1, 1, 2],
              [(0.012, 0, 0), (0.006, 0.015, 0), (0.01, 0.008, 0.012), (0.01, 0.01, 0)],
              [(0.01, 0.0, 0.0), (-0.015, 0.01, 0.0), (0.0, -0.015, 0.01), (0.015, 0.015, -0.015)],
              [rotation([1, 0, 0], 0.3).ravel(), rotation([0, 1, 1], 1.1).ravel(),
               rotation([1, 1, 0], -0.4).ravel(), rotation([0, 0, 1], 0.9).ravel()],
              rng.normal(scale=0.1, size=(4, 6)))
    com = rng.uniform(-0.05, 0.05, size=(3, 3))
    cm = ContactModel(n, np.arange(n), [0.3, 0.6, 1.0], ContactParams(stiffness=300.0, damping=0.5))
    for step in range(5):  # move nodes so friction anchors stretch (some stick, some slip)
        x = x + rng.normal(scale=3e-4, size=x.shape)
        res = cm.compute(x, v, *g, com, 1e-3)
    assert res.report.contacts.sum() > 20 and res.report.slipping.sum() > 0
    assert res.report.contacts.sum() > res.report.slipping.sum()
    total = res.forces.sum(axis=0) + res.tool_force.sum(axis=0)
    scale = np.abs(res.forces).sum()
    assert np.linalg.norm(total) <= 1e-12 * scale
    torque = np.cross(x, res.forces).sum(axis=0)
    torque_tools = (res.tool_torque + np.cross(com, res.tool_force)).sum(axis=0)
    assert np.linalg.norm(torque + torque_tools) <= 1e-12 * scale
    # the contact set is exactly the set of (node, geom) pairs with negative signed distance
    for gi in range(4):
        d, _, _ = signed_distance(x, g[0][gi], g[2][gi], g[3][gi], g[4][gi])
        assert np.array_equal(cm.in_contact[:, gi], d < 0)
    # per-tool report consistent with the per-geom values
    assert res.report.normal_force[1] == pytest.approx(res.geom_normal_force[1] + res.geom_normal_force[2])
    assert res.report.normal_force.sum() == pytest.approx(res.geom_normal_force.sum())


# ---------------------------------------------------------------------------------------------
# Friction: stick and slip
class Particle:
    """One node (mass m, kg) under contact forces, an external force and light damping."""

    def __init__(self, x, m=1e-3, damping=60.0):
        self.x = np.array([x], float)
        self.v = np.zeros((1, 3))
        self.m, self.b = m, damping

    def step(self, f, dt):
        self.v += dt * (f - self.b * self.m * self.v) / self.m
        self.x += dt * self.v


def test_stuck_node_follows_moving_and_rotating_box():
    k, mu, press = 200.0, 0.5, 0.2        # N/m, -, N
    cm = ContactModel(1, [0], [mu], ContactParams(stiffness=k, damping=0.05))
    h = np.array([0.02, 0.02, 0.005])
    p = Particle([0.005, 0.0, 0.0])
    box_pos = np.array([0.0, 0.0, -h[2]])   # top face at z = 0
    dt = 2e-4
    com = np.zeros((1, 3))
    speed = 0.01                            # m/s along x for 0.4 s (4 mm), then rotation about z
    for i in range(4000):
        t = i * dt
        vel = np.zeros(6)
        if t < 0.4:
            box_pos = box_pos + [speed * dt, 0, 0]
            vel[3] = speed
            R = np.eye(3)
            ang = 0.0
        else:
            ang = min(t - 0.4, 0.3) * 1.0   # 1 rad/s for 0.3 s about the box's z axis
            vel[2] = 1.0 if t - 0.4 < 0.3 else 0.0
            R = rotation([0, 0, 1], ang)
        res = cm.compute(p.x, p.v, [BOX], [0], [h], [box_pos], [R.ravel()], [vel], com, dt)
        p.step(res.forces + [0, 0, -press], dt)
        if abs(t - 0.4) < dt / 2:
            # after the translation the node has moved with the box (4 mm), lag below mu*f_n/k
            assert p.x[0, 0] == pytest.approx(0.005 + 0.004, abs=mu * press / k * 1.05)
            assert res.report.slipping[0] == 0
    # after the rotation the node sits at its stuck anchor rotated with the box about the box centre
    start_local = np.array([0.005 - 0.0, 0.0])  # node offset from the box centre (box moved with it)
    expect = box_pos[:2] + rotation([0, 0, 1], 0.3)[:2, :2] @ start_local
    assert np.linalg.norm(p.x[0, :2] - expect) < 0.05 * 0.005
    assert res.report.contacts[0] == 1 and res.report.slipping[0] == 0


def test_slip_caps_tangential_force_at_mu_fn():
    k, mu, press = 200.0, 0.6, 0.2
    cm = ContactModel(1, [0], [mu], ContactParams(stiffness=k, damping=0.0, tangential_stiffness=150.0))
    h = np.array([0.05, 0.05, 0.005])
    p = Particle([0.0, 0.0, 0.0])
    g = geoms([BOX], [0], [h], [(0, 0, -h[2])])
    com = np.zeros((1, 3))
    dt = 2e-4
    slid_at = None
    for i in range(6000):
        t = i * dt
        pull = 0.25 * t                      # N, ramped tangential load along +y
        res = cm.compute(p.x, p.v, *g, com, dt)
        f_ext = np.array([[0.0, pull, -press]])
        p.step(res.forces + f_ext, dt)
        if slid_at is None and res.report.slipping[0] == 1:
            slid_at = pull
        if slid_at is not None and pull > 1.3 * mu * press:
            break
    f_n = res.report.normal_force[0]
    f_t = res.report.tangential_force[0]
    assert res.report.slipping[0] == 1
    assert f_t == pytest.approx(mu * f_n, rel=0.01)
    assert -res.forces[0, 1] == pytest.approx(mu * f_n, rel=0.01)   # friction opposes the sliding
    assert slid_at == pytest.approx(mu * press, rel=0.05)          # slip starts when load reaches mu*f_n
    assert p.v[0, 1] > 0 and p.x[0, 1] > 3 * mu * press / 150.0   # it slides (beyond the stick stretch)


def test_contact_end_drops_anchor():
    cm = ContactModel(1, [0], [1.0], ContactParams(stiffness=100.0, damping=0.0))
    g = list(geoms([SPHERE], [0], [(0.01, 0, 0)], [(0, 0, 0)]))
    com = np.zeros((1, 3))
    x = np.array([[0.0, 0.0, 0.009]])
    cm.compute(x, np.zeros((1, 3)), *g, com, 1e-3)
    g[3] = np.array([[0.0005, 0.0, 0.0]])    # sphere shifted sideways: anchor stretched
    res = cm.compute(x, np.zeros((1, 3)), *g, com, 1e-3)
    assert res.report.tangential_force[0] > 0
    res = cm.compute(x + [0, 0, 0.01], np.zeros((1, 3)), *g, com, 1e-3)   # out of contact
    assert res.report.contacts[0] == 0 and not cm.in_contact.any()
    res = cm.compute(x, np.zeros((1, 3)), *g, com, 1e-3)                   # new contact: fresh anchor
    assert res.report.tangential_force[0] == 0.0


# ---------------------------------------------------------------------------------------------
# Parameters and validation
def test_auto_stiffness_is_explicitly_stable():
    masses = np.array([2e-4, 5e-5, 1e-4])
    dt = 1e-3
    k = auto_stiffness(masses, dt)
    assert k * dt**2 / masses.min() == pytest.approx(0.1)
    cm = ContactModel(3, [0, 1, 2], [0.5], ContactParams(stiffness="auto"), node_masses=masses)
    assert cm.stiffness_for(dt) == pytest.approx(k)
    assert cm.stiffness_for(dt / 2) == pytest.approx(4 * k)


def test_bad_inputs_raise_config_errors():
    with pytest.raises(ConfigError, match="stiffness"):
        ContactParams(stiffness=-1.0)
    with pytest.raises(ConfigError, match="node_masses"):
        ContactModel(3, [0], [0.5], ContactParams(stiffness="auto"))
    with pytest.raises(ConfigError, match="tool_friction"):
        ContactModel(3, [0], [-0.1])
    with pytest.raises(ConfigError, match="duplicates"):
        ContactModel(3, [0, 0], [0.5])
    cm = ContactModel(2, [0, 1], [0.5])
    x = np.zeros((2, 3))
    with pytest.raises(ConfigError, match="shape_kind"):
        cm.compute(x, x, *geoms([9], [0], [(0.01, 0, 0)], [(0, 0, 0)]), np.zeros((1, 3)), 1e-3)
    with pytest.raises(ConfigError, match="shape_tool"):
        cm.compute(x, x, *geoms([SPHERE], [3], [(0.01, 0, 0)], [(0, 0, 0)]), np.zeros((1, 3)), 1e-3)
    with pytest.raises(ConfigError, match="positions"):
        cm.compute(np.zeros((3, 3)), x, *geoms([SPHERE], [0], [(0.01, 0, 0)], [(0, 0, 0)]), np.zeros((1, 3)), 1e-3)
    with pytest.raises(ConfigError, match="dt"):
        cm.compute(x, x, *geoms([SPHERE], [0], [(0.01, 0, 0)], [(0, 0, 0)]), np.zeros((1, 3)), 0.0)
