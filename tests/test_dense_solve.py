"""The numba kernels' small dense solve against LAPACK, and its refusal of a singular matrix."""

import numpy as np
import pytest

from surgsim_envs.tissue.dense_solve import solve_dense


@pytest.mark.parametrize("n", [1, 3, 12, 60])
def test_solves_contact_like_systems_as_lapack_does(n):
    # I + W diag(k), W symmetric positive definite: the system fem_static solves per step
    rng = np.random.default_rng(n)
    q = rng.standard_normal((n, n))
    w = q @ q.T / n + 1e-3 * np.eye(n)
    a = np.eye(n) + w * rng.uniform(0.0, 1e4, n)[None, :]
    b = rng.standard_normal(n)
    a0, b0 = a.copy(), b.copy()
    x = solve_dense(a, b)
    assert np.array_equal(a, a0) and np.array_equal(b, b0)          # inputs untouched
    ref = np.linalg.solve(a, b)
    assert np.max(np.abs(x - ref)) <= 1e-10 * np.max(np.abs(ref))
    assert np.max(np.abs(a @ x - b)) <= 1e-12 * (np.abs(a).sum(axis=1).max() * np.abs(x).max() + np.abs(b).max())


def test_needs_pivoting():
    # a zero on the diagonal: elimination without row exchanges would divide by it
    a = np.array([[0.0, 2.0, 1.0], [1.0, 1.0, 0.0], [3.0, 0.0, 1.0]])
    b = np.array([3.0, 2.0, 4.0])
    np.testing.assert_allclose(solve_dense(a, b), np.linalg.solve(a, b), rtol=1e-14, atol=1e-14)


def test_singular_matrix_is_refused():
    a = np.array([[1.0, 2.0], [2.0, 4.0]])
    with pytest.raises(ValueError, match="singular"):
        solve_dense(a, np.array([1.0, 1.0]))
