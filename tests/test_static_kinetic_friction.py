"""Static and kinetic friction in the contact law (contact/friction.py).

A sticking contact point holds up to mu_s f_n and then slides at mu f_n (mu_s >= mu); a sliding
point sticks again when its stick spring falls back to mu f_n. Exact checks on a uniformly loaded
patch (every point has the same normal force and moves the same way), where Coulomb's law with
two coefficients is the textbook one: the tangential force rises along the stick springs to
mu_s * N, drops to mu * N when the patch breaks away, stays there while it slides, holds when it
stops, and breaks away again at mu_s * N. The default (no static coefficient) is the old
single-coefficient law. The soft grasp (bench/material.slip) is in tests/test_slip_onset.py.
"""

import numpy as np
import pytest

from surgsim_envs.contact import BOX, ContactModel, ContactParams
from surgsim_envs.errors import ConfigError

K_N, K_T, DEPTH = 200.0, 400.0, 1e-3        # N/m per point, N/m per point, m (f_n = 0.2 N per point)


def _patch(mu, mu_s, n_side=4):
    xs = np.linspace(-0.006, 0.006, n_side)
    x = np.array([[a, b, 0.0] for a in xs for b in xs])
    cm = ContactModel(len(x), np.arange(len(x)), [mu],
                      ContactParams(stiffness=K_N, damping=0.0, tangential_stiffness=K_T),
                      tool_static_friction=None if mu_s is None else [mu_s])
    return cm, x


def _drag(cm, x, moves):
    """Move the patch along +x by each of ``moves`` (m) under a flat box jaw pressed DEPTH into it;
    return per call (|sum f_t| / sum f_n, sliding points, contact points)."""
    jaw = ([BOX], [0], [[0.05, 0.05, 0.01]], [[0.0, 0.0, 0.01 - DEPTH]], [np.eye(3).ravel()], np.zeros((1, 6)),
           np.zeros((1, 3)))
    v = np.zeros_like(x)
    out = []
    for dx in moves:
        x = x + np.array([dx, 0.0, 0.0])
        res = cm.compute(x, v, *jaw, 1e-3)
        rep = res.report
        out.append((rep.tangential_force[0] / rep.normal_force[0], int(rep.slipping[0]), int(rep.contacts[0])))
    return np.array(out)


@pytest.mark.parametrize("mu", [0.1, 0.3, 0.6, 1.2])
def test_patch_breaks_away_at_static_and_slides_at_kinetic(mu):
    mu_s = 1.5 * mu
    cm, x = _patch(mu, mu_s)
    step = 0.01 * mu * K_N * DEPTH / K_T            # 1 % of the kinetic stick length per call
    moves = [0.0] + [step] * 300 + [0.0] * 20 + [step] * 300
    r = _drag(cm, x, moves)
    ratio, sliding, contacts = r[:, 0], r[:, 1], r[:, 2]
    assert np.all(contacts == 16)
    first = int(np.argmax(sliding > 0))             # breakaway read from the contact state
    every = int(np.argmax(sliding == 16))
    assert every - first <= 1                        # the whole patch at once (to round-off: one call)
    assert ratio[first - 1] == pytest.approx(mu_s, rel=0.01)         # held up to mu_s N ...
    assert ratio[:first].max() <= mu_s * (1 + 1e-12)
    assert np.allclose(ratio[every:301], mu, rtol=1e-9)             # ... then slides at mu N
    assert np.all(sliding[every:301] == 16)
    held = slice(302, 321)                                            # stopped: sticks, at mu N
    assert np.all(sliding[held] == 0) and np.allclose(ratio[held], mu, rtol=1e-9)
    second = 321 + int(np.argmax(sliding[321:] > 0))                 # moving again: breaks away at mu_s N
    assert ratio[second - 1] == pytest.approx(mu_s, rel=0.01)
    assert ratio[second + 1] == pytest.approx(mu, rel=1e-9)


def test_default_is_one_coefficient_and_bad_static_coefficient_is_refused():
    cm, x = _patch(0.5, None)
    assert np.array_equal(cm.tool_static_friction, cm.tool_friction)
    r = _drag(cm, x, [0.0] + [0.01 * 0.5 * K_N * DEPTH / K_T] * 300)
    assert r[:, 0].max() == pytest.approx(0.5, rel=1e-9)             # never above mu: no static peak
    assert np.allclose(r[r[:, 1] > 0, 0], 0.5)
    cm2, x2 = _patch(0.5, 0.5)                                       # mu_s == mu: the same law exactly
    assert np.array_equal(_drag(cm2, x2, [0.0] + [0.01 * 0.5 * K_N * DEPTH / K_T] * 300), r)
    with pytest.raises(ConfigError, match="tool_static_friction"):
        _patch(0.5, 0.4)
    with pytest.raises(ConfigError, match="tool_static_friction"):
        ContactModel(2, [0, 1], [0.5], tool_static_friction=[0.6, 0.7])   # one per tool


@pytest.mark.slow
def test_slippage_task_exposes_the_static_coefficient():
    """Slippage-v0 draws the kinetic mu per episode; ``static_friction_ratio`` sets mu_s = ratio * mu
    on the jaws' contact (and in info); a ratio below 1 is refused."""
    import gymnasium as gym

    import surgsim_envs  # noqa: F401

    env = gym.make("SurgSim/Slippage-v0", static_friction_ratio=1.5)
    env.reset(seed=0)
    contact = next(iter(env.unwrapped.sim.contacts.values()))
    assert np.allclose(contact.tool_static_friction, 1.5 * contact.tool_friction)
    info = env.step(np.zeros(1, np.float32))[-1]
    assert info["mu_static"] == pytest.approx(1.5 * info["mu"])
    env.close()
    with pytest.raises(ConfigError, match="static_friction_ratio"):
        gym.make("SurgSim/Slippage-v0", static_friction_ratio=0.8)
