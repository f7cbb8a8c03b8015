"""A divergence names the cure that fits the step that diverged: a smaller dt for an explicit step,
not for an implicit one whose load inverted elements."""

import pickle

import numpy as np
import pytest

from surgsim_envs.errors import TissueUnstableError
from surgsim_envs.geometry import box_volume
from surgsim_envs.tissue import registry


def _crushed(integrator):
    vol = box_volume((0.01, 0.01, 0.01), 0.005, center=(0.0, 0.0, 0.005))
    bottom = np.isclose(vol.nodes[:, 2], 0.0)
    model = registry.get("fem")(vol, {"preset": "liver", "relax_fraction": 0.0}, fixed=bottom, integrator=integrator)
    top = np.flatnonzero(np.isclose(vol.nodes[:, 2], 0.01))
    f = np.zeros((model.n_nodes, 3))
    with pytest.raises(TissueUnstableError) as info:
        for k in range(2000):                # one node pushed slowly through the block
            f[top[0], 2] = -0.005 * k
            model.step(1e-3, f)
    return info.value


def test_an_implicit_step_that_inverts_elements_is_not_told_to_reduce_dt():
    err = _crushed("implicit")
    assert "inverted" in err.reason
    assert "implicit already" in str(err) and "Reduce dt" not in str(err)
    again = pickle.loads(pickle.dumps(err))          # async vector envs carry it across processes
    assert str(again) == str(err)


def test_the_explicit_advice_is_kept_for_other_failures():
    err = TissueUnstableError("fem", 1e-3, 2e-4, "non-finite positions")
    assert "Reduce dt below the critical estimate" in str(err)
