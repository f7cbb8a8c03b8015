"""MuJoCo's native 3-D flex baseline (surgsim_envs.bench.mujoco_flex): indentation force behaviour, bad input."""

import numpy as np
import pytest

from surgsim_envs.bench.mujoco_flex import flex_indent, flexcomp_xml
from surgsim_envs.errors import ConfigError

# a small slab (10 mm thick, 40 mm wide) so MuJoCo's full-dof flex stays a few hundred vertices
SMALL = dict(indenter_radius=0.005, depth=0.001, thickness=0.01, width=0.04, spacing=0.004, n_depths=4,
             ramp_time=0.02, hold_time=0.05)


@pytest.mark.parametrize("dof", ["full", "trilinear"])
def test_flex_indent_force_is_finite_positive_and_increasing(dof):
    res = flex_indent(dof, "liver", cellcount=2, **SMALL)
    assert np.all(np.isfinite(res.force)) and np.all(np.isfinite(res.penetration))
    assert np.all(res.force > 0)                      # the slab pushes the sphere up at every depth
    assert np.all(np.diff(res.force) > 0)             # deeper -> more force
    assert np.all(res.penetration >= 0) and np.all(res.penetration < res.depth)
    assert res.nodes > 0 and res.dofs > 0 and res.us_per_ms > 0


def test_trilinear_has_few_dofs_and_is_stiffer_than_full():
    # the interpolated flex cannot dent locally: same mesh, far fewer dofs, a stiffer response
    full = flex_indent("full", "liver", **SMALL)
    tri = flex_indent("trilinear", "liver", cellcount=1, **SMALL)
    assert tri.dofs < full.dofs / 10
    assert tri.force[-1] > full.force[-1]


def test_stiffer_material_gives_more_force():
    soft = flex_indent("trilinear", {"preset": "liver", "young": 2000.0}, cellcount=2, **SMALL)
    hard = flex_indent("trilinear", {"preset": "liver", "young": 8000.0}, cellcount=2, **SMALL)
    assert hard.force[-1] > 2.0 * soft.force[-1]


def test_bad_input_raises_config_error():
    with pytest.raises(ConfigError, match="dof"):
        flexcomp_xml("x", young=1e3, poisson=0.4, mass=1.0, dof="quadratic", count=(3, 3, 3), spacing=(1, 1, 1),
                     pos=(0, 0, 0))
    with pytest.raises(ConfigError, match="poisson"):
        flexcomp_xml("x", young=1e3, poisson=0.5, mass=1.0, count=(3, 3, 3), spacing=(1, 1, 1), pos=(0, 0, 0))
    with pytest.raises(ConfigError, match="depth"):
        flex_indent("full", "liver", **{**SMALL, "depth": 0.02})
    with pytest.raises(ConfigError, match="spacing"):
        flex_indent("full", "liver", **{**SMALL, "spacing": -1.0})
