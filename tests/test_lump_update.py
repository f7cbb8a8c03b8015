"""A lumpy world's compliance from one shared lump-free compliance (Woodbury) equals the compliance of
its own factorised stiffness, in Palpation-v0's scene (its slab, its lumps, its Young's scales)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import scipy.sparse.linalg as spla

import surgsim_envs  # noqa: F401  (registers the tasks)
from surgsim_envs.errors import ConfigError
from surgsim_envs.tissue.lump_update import LumpCompliance, dense_compliance, stiffness_change


@pytest.fixture(scope="module")
def slab():
    env = gym.make("SurgSim/Palpation-v0", spacing=0.01)
    env.reset(seed=0)
    tissue = env.unwrapped.sim.tissue()
    fdofs = np.flatnonzero(np.repeat(~tissue.fixed, 3))
    top = np.flatnonzero((tissue.rest_positions[:, 2] > tissue.rest_positions[:, 2].max() - 1e-9) & ~tissue.fixed)
    pos = np.full(3 * tissue.n_nodes, -1)
    pos[fdofs] = np.arange(len(fdofs))
    surface = pos[(3 * top[:, None] + np.arange(3)).ravel()]

    def free_stiffness():
        return tissue.stiffness_matrix().tocsc()[fdofs][:, fdofs].tocsc()

    tissue.scale_material("young", 1.0)
    k_unit = free_stiffness()
    yield env, free_stiffness, k_unit, dense_compliance(k_unit), surface
    env.close()


@pytest.mark.parametrize("seed", [1, 4])
def test_a_lumpy_worlds_columns_equal_its_own_factorisation(slab, seed):
    env, free_stiffness, k_unit, c0, surface = slab
    env.reset(seed=seed)
    scale = env.unwrapped.inclusion["young_scale"]
    assert scale != 1.0
    k = free_stiffness()
    world = LumpCompliance(c0, stiffness_change(k, k_unit, scale), scale)
    assert 0 < len(world.support) < 0.5 * k.shape[0], "the lump changes a local part of the slab"
    rhs = np.zeros((k.shape[0], len(surface)))
    rhs[surface, np.arange(len(surface))] = 1.0
    direct = spla.splu(k).solve(rhs)
    scale_of = np.abs(direct).max()
    np.testing.assert_allclose(world.columns(surface), direct, rtol=0, atol=1e-10 * scale_of)
    np.testing.assert_allclose(world.block(surface), direct[surface], rtol=0, atol=1e-10 * scale_of)
    # the lump is felt: the surface compliance differs from the lump-free slab's by far more than rounding
    assert np.abs(world.block(surface) - c0[np.ix_(surface, surface)] / scale).max() > 1e-3 * scale_of


def test_a_world_without_a_lump_is_the_shared_compliance_scaled(slab):
    env, free_stiffness, k_unit, c0, surface = slab
    env.reset(seed=2, options={"stiffness_contrast": (1.0, 1.0)})
    scale = env.unwrapped.inclusion["young_scale"]
    world = LumpCompliance(c0, stiffness_change(free_stiffness(), k_unit, scale), scale)
    assert len(world.support) == 0 and world.nbytes == 0
    np.testing.assert_array_equal(world.columns(surface[:6]), c0[:, surface[:6]] / scale)


def test_bad_input_names_the_value_and_the_fix(slab):
    _, _, k_unit, c0, _ = slab
    dk = stiffness_change(k_unit, k_unit, 1.0)
    n = c0.shape[0]
    with pytest.raises(ConfigError, match=r"scale=nan must be a finite Young's scale > 0"):
        LumpCompliance(c0, dk, float("nan"))
    with pytest.raises(ConfigError, match=r"scale=0.0 must be"):
        LumpCompliance(c0, dk, 0.0)
    with pytest.raises(ConfigError, match=r"dk has shape .* both are on the same free dofs"):
        LumpCompliance(c0[:-3, :-3], dk, 1.0)
    with pytest.raises(ConfigError, match=rf"free-dof indices in \[0, {n}\)"):
        LumpCompliance(c0, dk, 1.0).columns([0, n])
    with pytest.raises(ConfigError, match="square and non-empty"):
        dense_compliance(k_unit[:, :-1])
