"""The penalty contact with Coulomb friction against analytic references, on a quasi-static FEM
slab (bench.frictional_press, bench.contact_references). Fast representatives here; the refined
comparisons run with -m slow."""

import numpy as np
import pytest

from surgsim_envs.bench import contact_references as cr
from surgsim_envs.bench.frictional_press import frictional_press
from surgsim_envs.errors import ConfigError

MAT = {"preset": "liver", "relax_fraction": 0.0}


def test_bonded_punch_raises_the_load_by_mossakovskii_factor_fast():
    # a flat punch in full stick (mu 5) against the same punch frictionless, nu = 0: kappa = ln 3 = 1.099;
    # coarse mesh (radius / spacing 2.5), so 2 % (the refined slow case is within 1 %)
    mat = {**MAT, "poisson": 0.0}
    kw = dict(radius=0.005, depth=5e-5, thickness=0.025, spacing=0.002, press_steps=4, tool="punch")
    p0 = frictional_press(mat, mu=0.0, **kw).normal[-1]
    p1 = frictional_press(mat, mu=5.0, **kw).normal[-1]
    assert p1 / p0 == pytest.approx(cr.no_slip_stiffness_factor(0.0), rel=0.02)


def test_gross_sliding_carries_mu_n_fast():
    # a/R = 0.035 (little ploughing by the tilted normals); slid 1.6 mm, ~8 x the Cattaneo-Mindlin slip
    # displacement, in increments of 25 um (the slip decision is explicit, see bench.frictional_press)
    r = frictional_press(MAT, mu=0.5, radius=0.04, depth=5e-5, thickness=0.006, spacing=1e-3, slide=1.6e-3,
                         press_steps=3, slide_steps=64, penalty_ratio=2.0)
    ds = cr.mindlin_slip_displacement(0.5, r.normal[2], r.info["contact_radius"], 4000.0, 0.45)
    assert r.x[-1] > 6 * ds
    assert np.mean(r.sliding_fraction[-6:]) > 0.8
    np.testing.assert_allclose(r.tangential[-6:] / (0.5 * r.normal[-6:]), 1.0, rtol=0.02)


@pytest.mark.slow
def test_partial_slip_starts_at_the_bonded_circle_stiffness():
    # Cattaneo-Mindlin: the pressed sphere first resists a tangential displacement like a bonded circle of
    # the contact radius, dQ/d delta = 8 G a / (2 - nu), then softens as the slip annulus grows (concave),
    # below mu P. Coarse mesh (a / h = 2) and a slab 7 a thick on its base, so 10 % on the initial secant
    # stiffness (measured 8 s under load, so -m slow).
    r = frictional_press(MAT, mu=0.5, radius=0.04, depth=5e-5, thickness=0.01, spacing=7e-4, slide=1e-5,
                         press_steps=3, slide_steps=5, penalty_ratio=2.0)
    p0, a = r.normal[2], float(cr.hertz_contact_radius(r.normal[2], 0.04, 4000.0, 0.45))
    q, x = r.tangential[3:], r.x[3:]
    g = cr.shear_modulus(4000.0, 0.45)
    assert q[0] / x[0] == pytest.approx(8 * g * a / (2 - 0.45), rel=0.10)
    assert np.all(np.diff(q) > 0) and np.all(np.diff(np.diff(q)) < 0) and q[-1] < 0.5 * p0


def test_rig_refuses_bad_input():
    with pytest.raises(ConfigError, match="tool must be 'sphere' or 'punch'"):
        frictional_press(MAT, tool="cone")
    with pytest.raises(ConfigError, match="mu must be a Coulomb coefficient >= 0"):
        frictional_press(MAT, mu=-0.1)
    with pytest.raises(ConfigError, match="depth 0.006 m must be below half the radius"):
        frictional_press(MAT, depth=0.006)


@pytest.mark.slow
@pytest.mark.parametrize("nu", [0.0, 0.3, 0.45])
def test_bonded_punch_matches_mossakovskii(nu):
    # radius / spacing 3.3: 1.0891 / 1.0284 / 1.0033 against kappa 1.0986 / 1.0286 / 1.0028
    mat = {**MAT, "poisson": nu}
    kw = dict(radius=0.005, depth=5e-5, thickness=0.05, spacing=0.0015, press_steps=8, tool="punch")
    ratio = frictional_press(mat, mu=5.0, **kw).normal[-1] / frictional_press(mat, mu=0.0, **kw).normal[-1]
    assert ratio == pytest.approx(cr.no_slip_stiffness_factor(nu), rel=0.012)


@pytest.mark.slow
@pytest.mark.parametrize("nu", [0.0, 0.45])
def test_sphere_press_friction_raise_is_small_and_below_the_punch_factor(nu):
    # a sphere whose contact grows while it sticks: full stick raises the press force, by less than a
    # bonded punch of the same radius (kappa); d/R 0.01, mesh scaled with a (measured 1.049 at nu 0 and
    # 1.0000 at nu 0.45: friction hardly couples into the normal load of a near-incompressible tissue)
    mat = {**MAT, "poisson": nu}
    a = (0.01 * 1e-4) ** 0.5
    kw = dict(radius=0.01, depth=1e-4, thickness=10 * a, spacing=a / 2.5, press_steps=8)
    ratio = frictional_press(mat, mu=5.0, **kw).normal[-1] / frictional_press(mat, mu=0.0, **kw).normal[-1]
    assert 0.999 <= ratio <= cr.no_slip_stiffness_factor(nu)
