"""Small dense solvers used inside the numba fit kernels."""

import numpy as np
import pytest
import scipy.linalg

from curvature.fitting.linalg import (
    cholesky,
    eigh3,
    generalized_smallest,
    jacobi_eigh,
    smallest_eigvec,
)


@pytest.mark.parametrize("m", [3, 6, 9, 10])
def test_jacobi_matches_lapack(m):
    rng = np.random.default_rng(m)
    a = rng.normal(size=(m, m))
    a = a + a.T
    w, v = jacobi_eigh(a)
    np.testing.assert_allclose(w, np.linalg.eigvalsh(a), atol=1e-12)
    np.testing.assert_allclose(a @ v, v * w, atol=1e-12)
    np.testing.assert_allclose(v.T @ v, np.eye(m), atol=1e-12)


def test_eigh3_is_jacobi_bit_for_bit():
    """The unrolled 3x3 Jacobi gives jacobi_eigh's very bits, ties (equal eigenvalues, zeros,
    rank-deficient matrices) included: PCA normals moved to it must not change a result."""
    rng = np.random.default_rng(3)
    cases = [np.zeros((3, 3)), np.eye(3), np.diag([2.0, 1.0, 1.0]), np.diag([1.0, 1.0, 0.0])]
    for trial in range(3000):
        kind = trial % 3
        if kind == 0:
            cases.append(np.diag(rng.choice([0.0, 1.0, 2.0], 3)))
        else:
            b = rng.normal(size=(3, 3 - kind + 1))  # full rank, then rank 2
            cases.append(b @ b.T)
    for a in cases:
        w, v = jacobi_eigh(a)
        w3, v3 = eigh3(a)
        assert np.array_equal(w, w3) and np.array_equal(v, v3), a


def test_generalized_smallest_matches_scipy():
    rng = np.random.default_rng(1)
    b = rng.normal(size=(9, 30))
    c = rng.normal(size=(9, 40))
    mat, metric = b @ b.T, c @ c.T
    vec, lam, ok = generalized_smallest(mat, metric, 1e-12)
    ref = scipy.linalg.eigh(mat, metric, eigvals_only=True)
    assert ok
    assert lam == pytest.approx(ref[0], rel=1e-8)
    np.testing.assert_allclose(mat @ vec, lam * metric @ vec, atol=1e-8)


def test_smallest_eigvec_of_singular_matrix():
    rng = np.random.default_rng(2)
    b = rng.normal(size=(9, 8))
    mat = b @ b.T  # rank 8: an exact fit
    y, lam = smallest_eigvec(mat, 200, 1e-12)
    assert abs(lam) < 1e-12
    assert np.linalg.norm(mat @ y) < 1e-10
    assert np.linalg.norm(y) == pytest.approx(1.0)


def test_cholesky_reports_indefinite_instead_of_raising():
    _, ok = cholesky(np.array([[1.0, 2.0], [2.0, 1.0]]), 1e-12)
    assert not ok
    l, ok = cholesky(np.array([[4.0, 2.0], [2.0, 3.0]]), 1e-12)
    assert ok
    np.testing.assert_allclose(l @ l.T, [[4.0, 2.0], [2.0, 3.0]])


def test_moment_assembly_matches_direct_products():
    from curvature.fitting.moments import gradient_metric, moments4, scatter_matrix

    xs = np.random.default_rng(3).normal(size=(17, 3))
    s2 = np.sqrt(2.0)

    def basis(p):
        x, y, z = p
        return np.array([x * x, y * y, z * z, s2 * x * y, s2 * y * z, s2 * x * z, x, y, z, 1.0])

    def jac(p):
        x, y, z = p
        return np.array([[2 * x, 0, 0], [0, 2 * y, 0], [0, 0, 2 * z], [s2 * y, s2 * x, 0],
                         [0, s2 * z, s2 * y], [s2 * z, 0, s2 * x], [1, 0, 0], [0, 1, 0],
                         [0, 0, 1]])

    mom = moments4(xs)
    np.testing.assert_allclose(scatter_matrix(mom), sum(np.outer(basis(p), basis(p)) for p in xs),
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(gradient_metric(mom), sum(jac(p) @ jac(p).T for p in xs),
                               rtol=1e-12, atol=1e-12)
