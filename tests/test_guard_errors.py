"""Stability guard: the critical dt quoted comes from the last good state, and
non-finite external inputs are refused as bad input before they reach the state."""

from __future__ import annotations

import math

import numpy as np
import pytest

from surgsim_envs.errors import ConfigError, NonFiniteInputError, TissueUnstableError
from surgsim_envs.geometry.box import box_volume
from surgsim_envs.tissue import registry


def _pressed_box(model: str = "mass_spring"):
    vol = box_volume((0.04, 0.04, 0.02), 0.005)
    m = registry.make(model, vol, "liver", integrator="symplectic")
    m.set_fixed(np.flatnonzero(vol.nodes[:, 2] < 1e-9))
    f = np.zeros_like(m.positions)
    f[vol.nodes[:, 2] > 0.0199, 2] = -0.05
    return m, f


@pytest.mark.parametrize("factor", [1.5, 3.0, 30.0])
def test_unstable_error_quotes_the_critical_dt_of_the_last_good_state(factor):
    m, f = _pressed_box()
    crit0 = m.critical_dt()
    with pytest.raises(TissueUnstableError) as exc:
        for _ in range(3000):
            m.step(factor * crit0, f)
    diverged = m.critical_dt()  # what the old guard quoted: orders of magnitude too small
    assert diverged < 0.1 * crit0
    assert exc.value.critical_dt == pytest.approx(crit0, rel=0.05)
    msg = str(exc.value)
    assert f"critical dt {exc.value.critical_dt:.3g} s" in msg
    assert "evaluated on the last good state" in msg or "evaluated on the rest state" in msg
    assert exc.value.dt > exc.value.critical_dt  # the advice (reduce dt below it) is right


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_forces_are_refused_before_the_state_changes(bad):
    m, f = _pressed_box()
    for _ in range(5):
        m.step(1e-4, f)
    before = (m.positions.copy(), m.velocities.copy(), m.time, m.steps)
    g = f.copy()
    g[7, 1] = bad
    with pytest.raises(NonFiniteInputError, match=r"external forces hold .* N at node 7") as exc:
        m.step(1e-4, g)
    assert isinstance(exc.value, ConfigError) and not isinstance(exc.value, TissueUnstableError)
    np.testing.assert_array_equal(m.positions, before[0])
    np.testing.assert_array_equal(m.velocities, before[1])
    assert (m.time, m.steps) == before[2:]
    stiff = np.zeros(m.n_nodes)
    stiff[3] = bad
    with pytest.raises(NonFiniteInputError, match="contact stiffness hold .* N/m at node 3"):
        m.step(1e-4, f, stiff)
    m.step(1e-4, f)  # the model is still usable
    assert np.all(np.isfinite(m.positions))
