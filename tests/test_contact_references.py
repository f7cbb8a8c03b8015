"""Frictional contact references (bench.contact_references): limits, identities and bad input."""

import math

import numpy as np
import pytest

from surgsim_envs.bench import contact_references as cr
from surgsim_envs.bench.references import hertz_force
from surgsim_envs.errors import ConfigError


def test_no_slip_factor_known_values_and_incompressible_limit():
    assert cr.no_slip_stiffness_factor(0.5) == 1.0
    assert cr.no_slip_stiffness_factor(0.0) == pytest.approx(math.log(3.0), rel=1e-14)
    assert cr.no_slip_stiffness_factor(0.45) == pytest.approx(0.55 * math.log(1.2) / 0.1, rel=1e-14)
    assert 1.0027 < cr.no_slip_stiffness_factor(0.45) < 1.0028
    # the series used next to nu = 0.5 joins the closed form
    nu = 0.5 - 1.5e-6
    e = 1.0 - 2.0 * nu
    assert cr.no_slip_stiffness_factor(0.5 - 0.4e-6) == pytest.approx(
        (1 - nu) * math.log(1 + 2 * e) / e, rel=1e-9)
    # friction can only raise the load, less the closer to incompressible
    k = [cr.no_slip_stiffness_factor(v) for v in np.linspace(0.0, 0.5, 11)]
    assert all(a > b for a, b in zip(k[:-1], k[1:])) and k[-1] == 1.0


def test_dundurs_beta():
    assert cr.dundurs_beta(0.45) == pytest.approx(1.0 / 11.0, rel=1e-14)
    assert cr.dundurs_beta(0.5) == 0.0 and cr.dundurs_beta(0.0) == 0.5


def test_hertz_contact_radius_is_sqrt_r_d():
    d = np.array([1e-4, 5e-4, 2e-3])
    p = hertz_force(d, 0.01, 4000.0, 0.45)
    np.testing.assert_allclose(cr.hertz_contact_radius(p, 0.01, 4000.0, 0.45), np.sqrt(0.01 * d), rtol=1e-12)


def test_cattaneo_mindlin_curve():
    mu, p, a, young, nu = 0.5, 0.2, 0.003, 4000.0, 0.45
    ds = cr.mindlin_slip_displacement(mu, p, a, young, nu)
    g = young / (2 * (1 + nu))
    assert ds == pytest.approx(3 * mu * p * (2 - nu) / (16 * g * a), rel=1e-14)
    q = np.linspace(0.0, mu * p, 21)
    delta = cr.cattaneo_mindlin_displacement(q, mu, p, a, young, nu)
    assert delta[0] == 0.0 and delta[-1] == pytest.approx(ds, rel=1e-14)
    assert np.all(np.diff(delta) > 0)
    # the two closed forms invert each other
    np.testing.assert_allclose(cr.cattaneo_mindlin_force(delta, mu, p, a, young, nu), q, rtol=1e-12, atol=1e-15)
    # half the friction limit is reached at 1 - 2^(-2/3) = 37 % of the slip displacement
    assert cr.cattaneo_mindlin_displacement(mu * p / 2, mu, p, a, young, nu) == pytest.approx(
        ds * (1 - 0.5 ** (2 / 3)), rel=1e-12)
    # initial stiffness: a bonded circle, 8 G a / (2 - nu) (Mindlin 1949)
    h = 1e-9 * ds
    slope = cr.cattaneo_mindlin_force(h, mu, p, a, young, nu) / h
    assert slope == pytest.approx(8 * g * a / (2 - nu), rel=1e-6)
    # gross sliding beyond delta_s: mu P
    assert cr.cattaneo_mindlin_force(3 * ds, mu, p, a, young, nu) == pytest.approx(cr.coulomb_sliding_force(mu, p))


def test_bad_input_is_named():
    with pytest.raises(ConfigError, match=r"poisson must lie in \[0, 0.5\]"):
        cr.no_slip_stiffness_factor(0.6)
    with pytest.raises(ConfigError, match=r"tangential_force must lie in \[0, mu P\]"):
        cr.cattaneo_mindlin_displacement(0.2, 0.5, 0.2, 0.003, 4000.0, 0.45)
    with pytest.raises(ConfigError, match="displacement must be finite and >= 0"):
        cr.cattaneo_mindlin_force(-1e-3, 0.5, 0.2, 0.003, 4000.0, 0.45)
    with pytest.raises(ConfigError, match="young=0.0 must be > 0"):
        cr.shear_modulus(0.0, 0.45)
    with pytest.raises(ConfigError, match="normal_force must be finite and >= 0"):
        cr.hertz_contact_radius(np.nan, 0.01, 4000.0, 0.45)
