"""Analytic references: limits and known values."""

import numpy as np
import pytest

from surgsim_envs.bench import references as ref
from surgsim_envs.errors import ConfigError


def test_dimitriadis_tends_to_hertz_for_thick_layers():
    d = np.linspace(1e-5, 1e-3, 20)
    hertz = ref.hertz_force(d, 0.005, 5000.0, 0.45)
    thick = ref.dimitriadis_force(d, 0.005, 5000.0, 0.45, thickness=10.0)
    np.testing.assert_allclose(thick, hertz, rtol=1e-3)


def test_dimitriadis_bonded_stiffer_than_unbonded_and_hertz():
    d = np.linspace(1e-4, 1e-3, 10)
    args = (0.005, 5000.0, 0.49)
    bonded = ref.dimitriadis_force(d, *args, thickness=0.01, bonded=True)
    free = ref.dimitriadis_force(d, *args, thickness=0.01, bonded=False)
    hertz = ref.hertz_force(d, *args)
    assert np.all(bonded > free) and np.all(free > hertz)


def test_dimitriadis_incompressible_coefficient_matches_paper():
    # Dimitriadis et al. 2002 eq. 13 (bonded, nu = 0.5): 1 + 1.133 chi + 1.283 chi^2 + 0.769 chi^3 + 0.0975 chi^4
    radius, thickness, depth = 0.005, 0.01, 0.002
    chi = np.sqrt(radius * depth) / thickness
    poly = 1 + 1.133 * chi + 1.283 * chi ** 2 + 0.769 * chi ** 3 + 0.0975 * chi ** 4
    f = ref.dimitriadis_force(depth, radius, 3000.0, 0.5 - 1e-9, thickness)
    assert f == pytest.approx(ref.hertz_force(depth, radius, 3000.0, 0.5 - 1e-9) * poly, rel=2e-3)


def test_sls_limits():
    t = np.linspace(0, 20, 2001)
    s = ref.sls_ramp_hold_stress(t, 0.1, 1.0, 1000.0, 0.6, 1.0)
    # instantaneous (very fast ramp) peak -> E0 * strain, long-time -> E_inf * strain
    fast = ref.sls_ramp_hold_stress(np.array([1e-6, 50.0]), 0.1, 1e-6, 1000.0, 0.6, 1.0)
    assert fast[0] == pytest.approx(100.0, rel=1e-3)
    assert fast[1] == pytest.approx(40.0, rel=1e-6)
    assert s[-1] == pytest.approx(40.0, rel=1e-4)
    assert np.argmax(s) == np.searchsorted(t, 1.0)  # peak at the end of the ramp


def test_references_reject_bad_input():
    with pytest.raises(ConfigError, match="radius"):
        ref.hertz_force(0.001, -1.0, 1000.0, 0.4)
    with pytest.raises(ConfigError, match="relax_fraction"):
        ref.sls_ramp_hold_stress(1.0, 0.1, 1.0, 1000.0, 1.5, 1.0)
