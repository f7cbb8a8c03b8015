"""The layered wall's probe contact is unilateral and frictionless (``contact/unilateral_probe.py``):
no contact node pulls the probe, no free node sits inside the sphere, the force depends on the
pose only (not on the presses before) and rises with depth."""

import numpy as np
import pytest

from surgsim_envs.contact.kinematic_probe import KinematicProbe
from surgsim_envs.contact.unilateral_probe import UnilateralProbe
from surgsim_envs.geometry.anatomy import abdominal_wall_volume
from surgsim_envs.tissue import make

RADIUS = 0.005


def _wall(spacing=0.005, size=(0.08, 0.06), vol=None):
    vol = abdominal_wall_volume(spacing, size=size) if vol is None else vol
    model = make("layered", vol, fixed=vol.face_nodes(4))
    top = np.flatnonzero(vol.neighbours[:, 5] < 0)
    return model, top, float(vol.nodes[top, 2].max())


@pytest.fixture(scope="module")
def wall_volume():
    return abdominal_wall_volume(0.005, size=(0.08, 0.06))


@pytest.fixture
def wall(wall_volume):
    """A fresh model (no node held by another test's probe) on the shared 5 mm wall lattice."""
    return _wall(vol=wall_volume)


def _press(model, probe, z_top, x, y, depth, **kw):
    probe.press((x, y, z_top + RADIUS - depth), model.static_solve, **kw)
    assert probe.settled
    return float(probe.force()[2])


def _complementarity(model, probe, z_top, x, y, depth):
    """(largest pull of a contact node on the probe (N), largest penetration of a free node (m))."""
    pull = -model.internal_forces()[probe.nodes, 2].min() if len(probe.nodes) else 0.0
    rest = model.rest_positions[probe.candidates]
    r2 = (rest[:, 0] - x) ** 2 + (rest[:, 1] - y) ** 2
    under = r2 < RADIUS ** 2
    h = z_top + RADIUS - depth - np.sqrt(RADIUS ** 2 - r2[under])
    free = ~np.isin(probe.candidates[under], probe.nodes)
    pen = (model.positions[probe.candidates[under], 2] - h)[free]
    return pull, (pen.max() if len(pen) else -np.inf)


SITES = [(0.0013, 0.0007), (-0.012, 0.009), (0.021, -0.004)]


def test_contact_is_unilateral_and_the_pinned_probe_was_not(wall):
    """At shallow and deep presses no contact node pulls the probe (compressive reactions only) and
    no free node under the sphere lies inside it. The pinning probe, reaching the same poses from
    2 mm deeper, holds nodes that pull the probe down: the test can tell the two apart."""
    model, top, z_top = wall
    pinned_pull = 0.0
    for x, y in SITES:
        for depth in (0.002, 0.004, 0.006):
            probe = UnilateralProbe(model, top, RADIUS)
            f = _press(model, probe, z_top, x, y, depth)
            pull, pen = _complementarity(model, probe, z_top, x, y, depth)
            assert f > 0
            assert pull <= 1e-6 * f
            assert pen <= 1e-9
            probe.move_to((1.0, 1.0, 1.0))       # lift: free every node again
            old = KinematicProbe(model, top, RADIUS)
            for d in (depth + 0.002, depth):
                old.move_to((x, y, z_top + RADIUS - d))
                model.static_solve()
            pinned_pull = max(pinned_pull, -model.internal_forces()[old.nodes, 2].min())
            old.move_to((1.0, 1.0, 1.0))
    assert pinned_pull > 0.1   # N: the sticking contact this probe replaces


def test_same_pose_reached_two_ways_reads_the_same_force(wall):
    """A press, then presses elsewhere and deeper, then the same pose again: equal forces. The warm
    start (active set from the nodes held before) reaches the same solution as the cold one."""
    model, top, z_top = wall
    probe = UnilateralProbe(model, top, RADIUS)
    rng = np.random.default_rng(7)
    for x, y in SITES:
        depth = 0.0035
        fresh = _press(model, probe, z_top, x, y, depth)
        for _ in range(3):
            _press(model, probe, z_top, x + rng.uniform(-0.006, 0.006), y + rng.uniform(-0.006, 0.006),
                   rng.uniform(0.001, 0.008))
        again = _press(model, probe, z_top, x, y, depth, warm=True)
        _press(model, probe, z_top, x, y, 0.008)
        from_deeper = _press(model, probe, z_top, x, y, depth, warm=True)
        assert again == pytest.approx(fresh, rel=1e-6)
        assert from_deeper == pytest.approx(fresh, rel=1e-6)


def test_force_rises_with_depth(wall):
    """Deeper presses of a convex rigid tool into a linear elastic body never read less force: at
    three sites, 0.5-8 mm pressed from deep to shallow (the order in which a sticking contact holds
    nodes that pull the probe), the force is non-decreasing in depth and grows from the first
    contact on."""
    model, top, z_top = wall
    probe = UnilateralProbe(model, top, RADIUS)
    depths = np.arange(0.0005, 0.00801, 0.0005)
    for x, y in SITES:
        forces = np.array([_press(model, probe, z_top, x, y, d, warm=True) for d in depths[::-1]])[::-1]
        touching = forces > 0
        assert touching[-1] and np.all(np.diff(touching.astype(int)) >= 0)
        assert np.all(np.diff(forces[touching]) > 0)


def test_a_press_deeper_than_the_lattice_gap_always_touches(wall):
    """Nodal contact: a sphere footprint wider than half a lattice diagonal always covers a node,
    so at depth >= R - sqrt(R^2 - h^2 / 2) (1.47 mm for R = h = 5 mm) the force is never 0."""
    model, top, z_top = wall
    probe = UnilateralProbe(model, top, RADIUS)
    d_min = RADIUS - np.sqrt(RADIUS ** 2 - 0.005 ** 2 / 2)
    rng = np.random.default_rng(3)
    for _ in range(20):
        x, y = rng.uniform(-0.035, 0.035), rng.uniform(-0.025, 0.025)
        assert _press(model, probe, z_top, x, y, rng.uniform(d_min + 1e-5, 0.008)) > 0


def test_press_rejects_bad_input(wall):
    model, top, z_top = wall
    probe = UnilateralProbe(model, top, RADIUS)
    with pytest.raises(ValueError, match="probe centre must be 3 finite numbers"):
        probe.press((0.0, np.nan, z_top), model.static_solve)
    with pytest.raises(ValueError, match=r"max_iterations=0 is outside \[1, inf\]; give a positive integer"):
        probe.press((0.0, 0.0, z_top), model.static_solve, max_iterations=0)


@pytest.mark.slow
def test_unilateral_path_independent_and_monotone_on_a_finer_wall():
    """The same three properties on the 3 mm wall (6.5k nodes), presses at random sites."""
    model, top, z_top = _wall(0.003)
    probe = UnilateralProbe(model, top, RADIUS)
    rng = np.random.default_rng(11)
    for _ in range(4):
        x, y = rng.uniform(-0.03, 0.03), rng.uniform(-0.02, 0.02)
        forces = [_press(model, probe, z_top, x, y, d) for d in (0.002, 0.004, 0.006)]
        pull, pen = _complementarity(model, probe, z_top, x, y, 0.006)
        assert pull <= 1e-6 * forces[-1] and pen <= 1e-9
        assert np.all(np.diff(forces) > 0)
        back = _press(model, probe, z_top, x, y, 0.002, warm=True)
        assert back == pytest.approx(forces[0], rel=1e-6)


@pytest.mark.slow
def test_env_press_pairs_agree():
    """LayeredPalpation-v0: 60 press pairs at the same site with random presses between read the
    same force within 2 % (with the pinning probe, 35 % of such pairs differed by more than 5 %)."""
    import gymnasium as gym

    import surgsim_envs  # noqa: F401

    env = gym.make("SurgSim/LayeredPalpation-v0", max_episode_steps=10_000).unwrapped
    env.reset(seed=5)
    rng = np.random.default_rng(5)
    worst = 0.0
    for _ in range(60):
        a = np.r_[rng.uniform(-1, 1, 3), -1.0].astype(np.float32)
        f1 = env.step(a)[0][3]
        for _ in range(2):
            env.step(np.r_[rng.uniform(-1, 1, 3), -1.0].astype(np.float32))
        f2 = env.step(a)[0][3]
        if max(f1, f2) > 0:
            worst = max(worst, abs(f1 - f2) / max(f1, f2))
    assert worst < 0.02
