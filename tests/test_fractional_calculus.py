"""Variable-order fractional derivatives (the variable-order paper, eqs. 3-4): accuracy, order, limits, Scott-Blair."""

from __future__ import annotations

import math

import numpy as np
import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.tissue import fractional_calculus as fc


def _errors(p, q, kind, scheme, sizes=(100, 200, 400, 800)):
    errs = []
    for m in sizes:
        h = 1.0 / m
        t = h * np.arange(m + 1)
        d = fc.derivative(t ** p, h, q, kind=kind, scheme=scheme)
        errs.append(abs(d[-1] - fc.power_derivative(1.0, p, q)))
    return np.array(errs)


@pytest.mark.parametrize("q", [0.25, 0.5, 0.75])
@pytest.mark.parametrize("p", [2.0, 1.5])
def test_l1_caputo_of_power_converges_with_order_two_minus_q(p, q):
    errs = _errors(p, q, "caputo", "l1")
    orders = np.log2(errs[:-1] / errs[1:])
    assert np.allclose(orders, 2.0 - q, atol=0.05), orders
    assert errs[-1] / fc.power_derivative(1.0, p, q) < 2e-4


@pytest.mark.parametrize("q", [0.25, 0.5, 0.75])
def test_gl_riemann_liouville_of_power_is_first_order(q):
    errs = _errors(2.0, q, "rl", "gl")
    orders = np.log2(errs[:-1] / errs[1:])
    assert np.allclose(orders, 1.0, atol=0.03), orders


def test_l1_is_exact_for_linear_functions():
    h, q = 0.01, 0.4
    t = h * np.arange(101)
    d = fc.derivative(3.0 * t, h, q)
    assert np.allclose(d[1:], 3.0 * fc.power_derivative(t[1:], 1.0, q), rtol=1e-12)


def test_riemann_liouville_of_a_constant_is_the_power_law():
    # RL D^q 1 = t^-q / Gamma(1 - q): the relaxation of a Scott-Blair element after a unit strain step
    h, q = 1e-3, 0.4
    t = h * np.arange(1, 2001)
    f = np.ones(2001)
    exact = t ** -q / math.gamma(1 - q)
    l1 = fc.derivative(f, h, q, kind="rl")[1:]
    gl = fc.derivative(f, h, q, kind="rl", scheme="gl")[1:]
    assert np.allclose(l1, exact, rtol=1e-12)
    assert np.max(np.abs(gl - exact)[100:] / exact[100:]) < 2e-3
    assert np.all(fc.derivative(f, h, q, kind="caputo") == 0.0)   # Caputo ignores the constant


def test_limits_elastic_and_viscous():
    h = 0.01
    t = h * np.arange(200)
    f = np.sin(3 * t) + 0.5
    for scheme in fc.SCHEMES:
        assert np.allclose(fc.derivative(f, h, 0.0, kind="rl", scheme=scheme)[1:], f[1:], atol=1e-12)
        d1 = fc.derivative(f, h, 1.0, kind="rl", scheme=scheme)[1:]
        assert np.allclose(d1, np.diff(f) / h, atol=1e-12)
    assert np.allclose(fc.derivative(f, h, 0.0)[1:], f[1:] - f[0], atol=1e-12)
    # continuity at the ends of the order range
    for q_end, q_near in ((0.0, 1e-6), (1.0, 1 - 1e-6)):
        a = fc.derivative(f, h, q_end, kind="rl", scheme="gl")[1:]
        b = fc.derivative(f, h, q_near, kind="rl", scheme="gl")[1:]
        assert np.max(np.abs(a - b)) < 1e-3 * np.max(np.abs(a))


def test_piecewise_order_uses_the_current_pieces_order_over_the_whole_past():
    h = 1e-3
    t = h * np.arange(1001)
    f = t ** 2
    order = fc.PiecewiseOrder.uniform([0.2, 0.6, 0.4], 1.0)
    d = fc.derivative(f, h, order)
    for qi, sel in zip(order.values, (t < 1 / 3, (t >= 1 / 3) & (t < 2 / 3), t >= 2 / 3)):
        ref = fc.derivative(f, h, qi)
        assert np.array_equal(d[sel], ref[sel])
    assert order(0.5) == 0.6 and order(1.0) == 0.4 and order(5.0) == 0.4


def test_scott_blair_creep_inverts_the_derivative():
    # eta D^q eps = sigma0 H(t)  ->  eps = sigma0 t^q / (eta Gamma(1 + q))
    eta, sigma0, q, h = 2e3, 100.0, 0.35, 1e-3
    t = h * np.arange(3001)
    eps = fc.solve_for_input(np.full(len(t), sigma0 / eta), h, q)
    exact = sigma0 * t ** q / (eta * math.gamma(1 + q))
    rel = np.abs(eps - exact)[500:] / exact[500:]
    assert rel.max() < 3e-3
    # and it is the exact inverse of the GL derivative
    back = fc.derivative(eps, h, q, kind="rl", scheme="gl")
    assert np.allclose(back, sigma0 / eta, rtol=1e-10)


def test_short_memory_error_is_within_podlubnys_bound_and_shrinks_with_L():
    h, q = 1e-3, 0.5
    t = h * np.arange(4001)
    f = 1.0 - np.exp(-t / 0.2)
    full = fc.derivative(f, h, q, kind="rl", scheme="gl")
    errs = []
    for mem in (50, 200, 800):
        err = np.max(np.abs(fc.derivative(f, h, q, kind="rl", scheme="gl", memory=mem) - full))
        assert err <= fc.short_memory_bound(1.0, h, q, mem)
        errs.append(err)
    assert errs[0] > errs[1] > errs[2]


def test_bad_input_raises_config_error():
    with pytest.raises(ConfigError, match="order q"):
        fc.derivative(np.ones(5), 0.1, 1.5)
    with pytest.raises(ConfigError, match="time step"):
        fc.derivative(np.ones(5), -0.1, 0.5)
    with pytest.raises(ConfigError, match="memory"):
        fc.derivative(np.ones(5), 0.1, 0.5, memory=0)
    with pytest.raises(ConfigError, match="one more value"):
        fc.PiecewiseOrder((0.5,), (0.1,))
    with pytest.raises(ConfigError, match="finite"):
        fc.derivative(np.array([0.0, np.nan, 1.0]), 0.1, 0.5)
