"""The step's fast paths keep every result: fast paths give what the checked paths give,
the vectorised guard checks make the same decisions, the contact kernel's tighter rejection box
contains every geom, and the compiled loop's address table follows replaced tissue arrays."""

from __future__ import annotations

import math

import numpy as np
import pytest

from surgsim_envs.contact.model import geom_box_half_width
from surgsim_envs.contact.report import ContactReport
from surgsim_envs.contact.shapes import BOX, CAPSULE, CYLINDER, SPHERE, bounding_radius, local_outside
from surgsim_envs.errors import ConfigError
from surgsim_envs.scene.simulation import _report_rows
from surgsim_envs.scene.step.loop import POSITIONS_ROW
from surgsim_envs.tissue.guard import all_finite, first_non_finite, max_speed_squared, speed_within

#: Palpation-v0 on the explicit mass-spring network (its default model is the quasi-static FEM, which has no
#: compiled substep loop)
MASS_SPRING = {"model": "mass_spring", "spacing": 0.01}



def _numpy_report(r, idx):
    """Simulation.tool_contact_report's general (numpy) path for one tissue."""
    return {"normal_force": 0.0 + float(r.normal_force[idx].sum()),
            "tangential_force": 0.0 + float(r.tangential_force[idx].sum()),
            "contacts": int(r.contacts[idx].sum()), "slipping": int(r.slipping[idx].sum()),
            "penetration": max(0.0, float(r.penetration[idx].max()))}


@pytest.mark.parametrize("rows", [1, 2, 3, 4, 5, 7])
def test_report_rows_are_numpys_sums_bit_for_bit(rows):
    rng = np.random.default_rng(rows)
    for trial in range(300):
        T = rows + int(rng.integers(0, 3))
        r = ContactReport.zeros(T)
        r.normal_force[:] = rng.standard_normal(T) * 10.0 ** rng.uniform(-6, 2, T)
        r.tangential_force[:] = rng.standard_normal(T) * 10.0 ** rng.uniform(-6, 2, T)
        r.contacts[:] = rng.integers(0, 50, T)
        r.slipping[:] = rng.integers(0, 50, T)
        r.penetration[:] = rng.uniform(0, 1e-3, T)
        if trial % 7 == 0:
            r.normal_force[:] = -0.0
        idx = np.sort(rng.choice(T, rows, replace=False))
        fast, ref = _report_rows(r, idx.tolist()), _numpy_report(r, idx)
        assert fast.keys() == ref.keys()
        for k in ref:
            assert type(fast[k]) is type(ref[k]) and fast[k] == ref[k], k
            assert math.copysign(1.0, fast[k]) == math.copysign(1.0, ref[k]), k    # the sign of zero too


def test_guard_checks_decide_as_before():
    rng = np.random.default_rng(0)
    limit2 = 20.0 ** 2
    for n in (1, 7, 232, 363):
        pos, vel, f = rng.standard_normal((n, 3)), rng.standard_normal((n, 3)), rng.standard_normal((n, 3))
        cases = [None, ("vel", 30.0), ("vel", 20.0), ("vel", np.nan), ("pos", np.inf), ("pos", -np.inf),
                 ("f", np.nan), ("f", np.inf), ("vel", 1e200)]
        for case in cases:
            p, v, ff = pos.copy(), vel.copy(), f.copy()
            if case is not None:
                {"pos": p, "vel": v, "f": ff}[case[0]][n // 2, 1] = case[1]
            v2 = max_speed_squared(p, v)
            assert speed_within(p, v, limit2) == (not (not np.isfinite(v2) or v2 > limit2)), case
            assert all_finite(ff) == (first_non_finite(ff) < 0), case
            assert all_finite(ff[:, 0].copy()) == (first_non_finite(ff[:, 0].copy()) < 0), case


@pytest.mark.parametrize("kind,size", [(SPHERE, (0.01, 0, 0)), (CAPSULE, (0.003, 0.05, 0)),
                                       (BOX, (0.0015, 0.006, 0.02)), (CYLINDER, (0.005, 0.06, 0))])
def test_geom_box_contains_the_whole_shape(kind, size):
    rng = np.random.default_rng(kind)
    sz = np.array([size], dtype=float)
    r = bounding_radius(kind, *size)
    s0, s1, s2 = size
    ext = {SPHERE: (s0, s0, s0), CAPSULE: (s0, s0, s1 + s0), BOX: (s0, s1, s2), CYLINDER: (s0, s0, s1)}[kind]
    inside = tight = 0
    for _ in range(200):
        q, _ = np.linalg.qr(rng.standard_normal((3, 3)))        # a random rotation (world <- local)
        gmat = q.reshape(1, 9)
        h = np.array([geom_box_half_width(kind, sz, gmat, 0, k, r) for k in range(3)])
        tight += bool(np.all(h < r))
        local = rng.uniform(-1.05, 1.05, (400, 3)) * ext        # around the shape's local box
        world = local @ q.T
        for lq, w in zip(local, world):
            if not local_outside(kind, size[0], size[1], size[2], *lq):
                inside += 1
                assert np.all(np.abs(w) <= h), "a point inside the shape fell outside its box"
    assert inside > 20000
    if kind != SPHERE:
        assert tight > 100, "the box should be tighter than the bounding sphere for elongated shapes"


def _env(task="SurgSim/Palpation-v0"):
    import gymnasium as gym

    import surgsim_envs  # noqa: F401

    env = gym.make(task, **(MASS_SPRING if "Palpation" in task else {}))
    env.reset(seed=0)
    return env


def test_action_fast_path_matches_the_checked_path():
    env = _env()
    u = env.unwrapped
    for a in ([0.3, -2.0, 1.5, -0.0], [1.0, -1.0, 0.999, 5e-324]):
        for dtype in (np.float32, np.float64):
            x = np.array(a, dtype=dtype)
            fast = u.check_action(x)
            slow = u.check_action(x.tolist())          # a list takes the checked path
            assert fast.dtype == np.float64 and np.array_equal(fast, slow)
            assert [math.copysign(1, v) for v in fast] == [math.copysign(1, v) for v in slow]
            assert fast is not x and np.array_equal(x, np.array(a, dtype=dtype))   # input untouched
    for bad in (np.array([np.nan, 0, 0, 0], dtype=np.float32), np.array([0, np.inf, 0, 0]),
                np.array([1e308, 1e308, 0, 0])):
        if np.isfinite(bad).all():
            assert np.array_equal(u.check_action(bad), [1.0, 1.0, 0.0, 0.0])     # overflowing sum: checked path
        else:
            with pytest.raises(ConfigError, match="NaN or inf"):
                u.check_action(bad)
    env.close()


def test_tool_target_fast_path_matches_the_checked_path():
    env = _env()
    sim = env.unwrapped.sim
    tool = sim.tool("probe")
    act = tool.actuator_ids[:3]
    rng = np.random.default_rng(1)
    for _ in range(20):
        target = tool.home + rng.uniform(-0.8, 0.8, 3) * tool.config.travel
        sim.set_tool_target("probe", target, speed=0.15)            # fast path (array)
        fast = (sim._goal[act].copy(), sim._rate[act].copy())
        sim.set_tool_target("probe", target.tolist(), speed=0.15)   # checked path (list)
        assert np.array_equal(fast[0], sim._goal[act]) and np.array_equal(fast[1], sim._rate[act])
    with pytest.raises(ConfigError, match="outside tool 'probe''s reach"):
        sim.set_tool_target("probe", tool.home + np.array([0.0, 0.0, 2.0 * tool.config.travel]))
    with pytest.raises(ConfigError, match="3 finite numbers"):
        sim.set_tool_target("probe", np.array([np.nan, 0.0, 0.0]))
    with pytest.raises(ConfigError, match="speed must be a positive number"):
        sim.set_tool_target("probe", tool.home.copy(), speed=-1.0)
    env.close()


def test_replaced_tissue_arrays_reach_the_compiled_loop():
    """The address table is keyed on the tissue's state version and the identity of its positions:
    assigning a new positions array must repack it, or the loop would step freed memory; reset()
    replaces arrays and bumps the version (notify_changed())."""
    env = _env()
    sim = env.unwrapped.sim
    tissue = sim.tissue()
    runner = sim.compiled_runner()
    assert runner is not None
    sim.step()
    v0 = tissue.state_version
    tissue.time = 1.0                                   # a scalar: no bump
    assert tissue.state_version == v0
    lifted = tissue.positions + np.array([0.0, 0.0, 1e-4])
    lifted[tissue.fixed] = tissue.positions[tissue.fixed]
    tissue.positions = lifted                           # a new array, followed by identity
    before = lifted.copy()
    sim.step()
    assert tissue.positions is lifted
    assert runner._table.table[POSITIONS_ROW, 0] == lifted.ctypes.data
    assert not np.array_equal(lifted, before), "the loop did not step the new positions array"
    tissue.reset()
    assert tissue.state_version > v0
    sim.step()
    assert runner._table.table[POSITIONS_ROW, 0] == tissue.positions.ctypes.data
    env.close()
