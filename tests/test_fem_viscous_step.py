"""The fused explicit step of the viscoelastic FEM (fem_viscous.symplectic_step, single thread) against
the unfused sequence the parallel path still runs: commit the branches, add their excess stress as
element forces, then the elastic step. Same physics; only the order of floating-point sums differs."""

import numpy as np
import pytest

from surgsim_envs import tissue
from surgsim_envs.geometry import box_volume

VISCO = {"young": 1.0e4, "poisson": 0.45, "density": 1000.0, "damping": 0.0, "relax_fraction": 0.5,
         "relax_time": 0.01}


@pytest.mark.parametrize("formulation,beta", [("anp", 0.0), ("standard", 0.0), ("anp", 1e-4)])
def test_fused_viscoelastic_step_matches_the_unfused_sequence(formulation, beta):
    vol = box_volume((0.03, 0.02, 0.02), 0.005)
    x = vol.nodes[:, 0]
    runs = []
    for threads in (1, 2):     # 1: fused kernel; 2: commit + excess forces + parallel elastic step
        model = tissue.make("fem", vol, VISCO, integrator="symplectic", threads=threads, formulation=formulation,
                            stiffness_damping=beta, fixed=x < x.min() + 1e-9)
        forces = np.zeros((vol.n_nodes, 3))
        forces[x > x.max() - 1e-9, 2] = -1e-3
        for k in range(60):
            model.step(4e-4 if k < 30 else 3e-4, forces)     # a dt change: the branch spans the previous one
        runs.append((model.positions.copy(), model.element_stress(), model.elastic_energy()))
    scale = np.abs(runs[0][0] - vol.nodes).max()
    assert scale > 1e-4
    np.testing.assert_allclose(runs[0][0], runs[1][0], rtol=0, atol=1e-9 * scale)
    stress = np.abs(runs[1][1]).max()
    np.testing.assert_allclose(runs[0][1], runs[1][1], rtol=0, atol=1e-9 * stress)
    assert abs(runs[0][2] - runs[1][2]) < 1e-9 * runs[1][2]


def test_explicit_branches_relax_the_stress_of_a_held_shape():
    """After the load is held for many relaxation times, the viscoelastic body carries the relaxed
    stress: its element stress is (1 - g) of the same body's instantaneous elastic stress at that shape."""
    vol = box_volume((0.03, 0.02, 0.02), 0.005)
    x = vol.nodes[:, 0]
    model = tissue.make("fem", vol, dict(VISCO, damping=50.0), integrator="symplectic", fixed=x < x.min() + 1e-9)
    forces = np.zeros((vol.n_nodes, 3))
    forces[x > x.max() - 1e-9, 2] = -1e-3
    for _ in range(1500):                      # 0.6 s = 60 relaxation times
        model.step(4e-4, forces)
    elastic = tissue.make("fem", vol, dict(VISCO, relax_fraction=0.0), fixed=x < x.min() + 1e-9)
    elastic.positions = model.positions.copy()
    relaxed, instant = model.element_stress(), elastic.element_stress()
    big = np.abs(instant) > 0.1 * np.abs(instant).max()
    np.testing.assert_allclose(relaxed[big], 0.5 * instant[big], rtol=0.02)


@pytest.mark.parametrize("formulation", ["anp", "standard"])
def test_commit_forces_equals_stress_then_branch_then_element_forces(formulation):
    """fem_viscous.commit_forces (one kernel) against its definition: corotated_stress, the branch
    recursion in numpy and add_stress_forces, on a deformed, rotated state with a branch history."""
    from surgsim_envs.tissue import fem_viscous as visc

    vol = box_volume((0.02, 0.02, 0.01), 0.005)
    m = tissue.make("fem", vol, VISCO, formulation=formulation)
    rng = np.random.default_rng(3)
    x = vol.nodes + 1e-3 * rng.standard_normal(vol.nodes.shape)
    m._update_rotations(x, tol=1e-12)
    nt = len(m.tets)
    h0 = rng.standard_normal((nt, 3, 3))
    h0 = h0 + h0.transpose(0, 2, 1)
    s_prev = rng.standard_normal((nt, 3, 3))
    s_prev = s_prev + s_prev.transpose(0, 2, 1)
    decay, gamma = rng.uniform(0.5, 1.0, nt), rng.uniform(0.5, 1.0, nt)
    keep, take = rng.uniform(0.5, 1.0, nt), rng.uniform(0.5, 1.0, nt)
    g = m.relax_g
    # reference
    sig0 = np.empty((nt, 3, 3))
    visc.corotated_stress(x, m.tets, m.dm_inv, m.tet_volume, m._rots, m.mu, m.lam, m._anp, m.kappa_node,
                          m.node_volume, np.zeros(nt), np.zeros(m.n_nodes), sig0)
    h_ref = decay[:, None, None] * h0 + gamma[:, None, None] * (sig0 - s_prev)
    excess = g[:, None, None] * (keep[:, None, None] * h_ref - take[:, None, None] * sig0)
    f_ref = np.ones((m.n_nodes, 3))
    visc.add_stress_forces(m.tets, m.grads, m.tet_volume, m._rots, np.ascontiguousarray(excess), f_ref)
    # kernel
    h, sp = h0.copy(), s_prev.copy()
    f = np.ones((m.n_nodes, 3))
    visc.commit_forces(x, m.tets, m.dm_inv, m.tet_volume, m._rots, m.mu, m.lam, m._anp, m.kappa_node, m.node_volume,
                       g, decay, gamma, h, sp, keep, take, np.empty((nt, 6)), np.empty(m.n_nodes), f)
    np.testing.assert_allclose(h, h_ref, rtol=0, atol=1e-12 * np.abs(h_ref).max())
    np.testing.assert_allclose(sp, sig0, rtol=0, atol=1e-12 * np.abs(sig0).max())
    np.testing.assert_allclose(f, f_ref, rtol=0, atol=1e-12 * np.abs(f_ref - 1).max())
    assert np.abs(f_ref - 1).max() > 1e-6
