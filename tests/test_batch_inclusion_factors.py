"""A batched reset's lump computed on the device (batch/inclusions.py, batch/inclusion_kernels.py) against
the single env's host computation (``tissue_setup.inclusion_young_factors``), and the per-world spring
constants written from device factors (``BatchSimulation.set_young_factor_array``) against the host
path (``set_young_factors``), on Warp's CPU device.

The fractions are counts of the same sample points, so the factors agree to rounding; the bound is
1e-14 relative (a sample point within rounding of the sphere could flip one tet by 1/1000 of its
share: no such point occurs in these draws, and the bound would then fail loudly)."""

import numpy as np
import pytest

from surgsim_envs.batch.backend import available
from surgsim_envs.errors import ConfigError

pytestmark = pytest.mark.skipif(not available(), reason="needs the [batch] extra (warp-lang, mujoco-warp)")


@pytest.fixture(scope="module")
def venv():
    from gymnasium.envs.registration import load_env_creator

    from surgsim_envs.envs import BATCHED

    env = load_env_creator(BATCHED["SurgSim/Palpation-v0"])(3, device="cpu")
    env.reset(seed=0)
    yield env
    env.close()


def test_device_factors_equal_the_single_envs_lump(venv):
    from surgsim_envs.batch.inclusions import SphereInclusionFactors
    from surgsim_envs.envs.tissue_setup import inclusion_young_factors

    tissue = venv.template.sim.tissue()
    device = SphereInclusionFactors(tissue.element_vertices(), "cpu")
    rng = np.random.default_rng(7)
    lo, hi = tissue.rest_positions.min(axis=0), tissue.rest_positions.max(axis=0)
    centres = [rng.uniform(lo, hi) for _ in range(12)]
    radii = list(rng.uniform(0.003, 0.012, 12))
    centres += [lo + 0.3 * (hi - lo), hi + [0.0, 0.0, 0.05], 0.5 * (lo + hi)]   # tiny, outside, whole-tet
    radii += [1e-4, 0.004, 0.03]
    contrasts = list(rng.uniform(1.5, 8.0, len(radii)))
    scales = list(rng.uniform(0.5, 2.0, len(radii)))
    got = device.factors(np.array(centres), radii, contrasts, scales).numpy()
    for k in range(len(radii)):
        want = inclusion_young_factors(tissue, centres[k], radii[k], contrasts[k], scales[k])
        np.testing.assert_allclose(got[k], want, rtol=1e-14, atol=0, err_msg=f"sphere {k}")
    stiff = got > np.array(scales)[:, None] * (1 + 1e-12)
    assert stiff[-3].sum() == 1            # the tiny sphere: its volume in the nearest tet
    assert stiff[-2].sum() == 1            # a sphere above the slab: the nearest tet takes its volume
    assert stiff[-1].sum() > 20            # a 3 cm sphere holds whole tets


def test_spring_constants_from_device_factors_equal_the_host_path(venv):
    import warp as wp

    sim = venv.sim
    T = sim.material_tets
    rng = np.random.default_rng(3)
    f = rng.uniform(0.5, 3.0, (2, T))
    keys = ("K1", "K2", "kM", "kMg", "kv")
    sim.set_young_factors(f, worlds=[2, 0])
    host = {k: getattr(sim.fields, k).numpy().copy() for k in keys}
    sim.set_young_factors(np.ones((3, T)))
    untouched = {k: getattr(sim.fields, k).numpy()[1].copy() for k in keys}
    sim.set_young_factor_array(wp.array(f, dtype=wp.float64, device="cpu"),
                               wp.array(np.array([2, 0], np.int32), dtype=wp.int32, device="cpu"))
    for k in keys:
        dev = getattr(sim.fields, k).numpy()
        np.testing.assert_allclose(dev[[0, 2]], host[k][[0, 2]], rtol=1e-14, atol=0, err_msg=k)
        np.testing.assert_array_equal(dev[1], untouched[k], err_msg=f"{k}: world 1 is not listed")
    with pytest.raises(ConfigError, match=r"factors must be a float64 Warp array \(k, \d+\) and worlds an int32 "
                                          r"Warp array \(k,\); got ndarray .* give numpy factors to set_young_factors"):
        sim.set_young_factor_array(f, np.array([2, 0]))
