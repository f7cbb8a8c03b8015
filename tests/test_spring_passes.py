"""The three-pass spring kernel (msd_kernels.spring_forces_passes, used by the symplectic step)
against the single-pass reference spring_forces: same nodal forces and Maxwell-branch update to
rounding, on a perturbed lattice with nonlinear springs and live branches; any spring order; a
zero-length spring exerts no force; and the symplectic step with the work buffer equals the
allocating one bit for bit."""

from __future__ import annotations

import numpy as np

from surgsim_envs.tissue import msd_kernels as kern


def _network(seed=0, n=6):
    """A perturbed n x n x n lattice with its 3-D diagonals: springs sorted by first node."""
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(*(np.arange(n),) * 3, indexing="ij"), -1).reshape(-1, 3) * 0.01
    idx = np.arange(n ** 3).reshape(n, n, n)
    pairs = []
    for d in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, 0, 1), (0, 1, 1), (1, 1, 1)]:
        a = idx[:n - d[0], :n - d[1], :n - d[2]].ravel()
        b = idx[d[0]:, d[1]:, d[2]:].ravel()
        pairs.append(np.stack([a, b], 1))
    e = np.concatenate(pairs)
    e = e[np.lexsort((e[:, 1], e[:, 0]))]
    si, sj = e[:, 0].copy(), e[:, 1].copy()
    L0 = np.linalg.norm(g[sj] - g[si], axis=1)
    pos = g + rng.normal(0, 1e-3, g.shape)          # strained: up to ~30 % per spring
    E = len(si)
    K1 = rng.uniform(5, 50, E)
    K2 = rng.uniform(1e4, 1e6, E)
    kMg = rng.uniform(1, 20, E)
    decay = np.full(E, 0.999)
    s = rng.normal(0, 1e-3, E)
    dl = rng.normal(0, 1e-4, E)
    return pos, si, sj, L0, K1, K2, kMg, decay, s, dl


def _both(pos, si, sj, L0, K1, K2, kMg, decay, s, dl, commit):
    s1, dl1, s2, dl2 = s.copy(), dl.copy(), s.copy(), dl.copy()
    f1, f2 = np.zeros_like(pos), np.full_like(pos, np.nan)      # the passes overwrite f_out
    work = np.full((4, len(si)), np.nan)                        # and any work buffer content
    kern.spring_forces(pos, si, sj, L0, K1, K2, kMg, decay, s1, dl1, commit, f1)
    kern.spring_forces_passes(pos, si, sj, L0, K1, K2, kMg, decay, s2, dl2, commit, f2, work)
    return (f1, s1, dl1), (f2, s2, dl2)


def test_passes_match_the_single_pass_kernel_to_rounding():
    args = _network()
    for commit in (False, True):
        (f1, s1, dl1), (f2, s2, dl2) = _both(*args, commit)
        scale = np.abs(f1).max()
        assert scale > 1e-3                                     # a real load, not zeros
        np.testing.assert_allclose(f2, f1, rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(s2, s1, rtol=1e-12, atol=1e-18)
        np.testing.assert_allclose(dl2, dl1, rtol=1e-12, atol=1e-18)
        assert np.all(np.abs(f1.sum(axis=0)) < 1e-12 * scale)   # internal forces sum to zero
        assert np.all(np.abs(f2.sum(axis=0)) < 1e-12 * scale)


def test_any_spring_order_gives_the_same_forces():
    pos, si, sj, L0, K1, K2, kMg, decay, s, dl = _network(seed=1)
    perm = np.random.default_rng(2).permutation(len(si))        # springs no longer sorted by si
    (f1, _, _), _ = _both(pos, si, sj, L0, K1, K2, kMg, decay, s, dl, False)
    _, (f2, _, _) = _both(pos, si[perm], sj[perm], L0[perm], K1[perm], K2[perm], kMg[perm], decay[perm], s[perm],
                          dl[perm], False)
    np.testing.assert_allclose(f2, f1, rtol=0, atol=1e-12 * np.abs(f1).max())


def test_zero_length_spring_exerts_no_force():
    pos = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.01, 0.0, 0.0]])
    si, sj = np.array([0, 0]), np.array([1, 2])
    one = np.ones(2)
    f = np.zeros_like(pos)
    kern.spring_forces_passes(pos, si, sj, np.array([0.01, 0.005]), 10 * one, 0 * one, 0 * one, one, 0 * one,
                              0 * one, False, f, np.empty((4, 2)))
    assert np.all(np.isfinite(f))
    np.testing.assert_allclose(f[1], 0.0)                       # only the coincident pair's spring: nothing
    np.testing.assert_allclose(f[2], [-0.05, 0, 0])             # 10 N/m x 5 mm in tension pulls node 2 back
    np.testing.assert_allclose(f[0], [0.05, 0, 0])


def test_symplectic_step_with_and_without_a_work_buffer_are_identical():
    pos, si, sj, L0, K1, K2, kMg, decay, s, dl = _network(seed=3)
    n = len(pos)
    rng = np.random.default_rng(4)
    vel = rng.normal(0, 1e-3, pos.shape)
    inv_mass = np.full(n, 1e3)
    b0 = np.full(n, 1e-3)
    fext = rng.normal(0, 1e-2, pos.shape)
    fixed = np.zeros(n, dtype=np.bool_)
    fixed[:5] = True
    none4, none = np.zeros((0, 4), dtype=np.int64), np.zeros(0)
    a = [pos.copy(), vel.copy(), s.copy(), dl.copy()]
    b = [pos.copy(), vel.copy(), s.copy(), dl.copy()]
    for _ in range(20):
        kern.symplectic_step(a[0], a[1], inv_mass, b0, fext, np.zeros(3), fixed, 1e-4, si, sj, L0, K1, K2, kMg, decay,
                             a[2], a[3], np.zeros_like(pos), none4, none, none)
        kern.symplectic_step_work(b[0], b[1], inv_mass, b0, fext, np.zeros(3), fixed, 1e-4, si, sj, L0, K1, K2, kMg,
                                  decay, b[2], b[3], np.zeros_like(pos), none4, none, none, np.empty((4, len(si))))
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    np.testing.assert_array_equal(a[0][:5], pos[:5])            # fixed nodes untouched
