"""Small dense linear algebra for per-point fits, written for numba.

LAPACK calls from numba allocate and carry call overhead that dominates for 3x3..10x10 systems,
and they raise on failure; these routines return a success flag instead so a bad point becomes a
status code, never an exception.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def jacobi_eigh(a_in):
    """Eigen-decomposition of a small symmetric matrix by cyclic Jacobi rotations.

    Parameters
    ----------
    a_in : ndarray, shape (m, m)
        Symmetric matrix (not modified).

    Returns
    -------
    w : ndarray, shape (m,)
        Eigenvalues in ascending order.
    v : ndarray, shape (m, m)
        Orthonormal eigenvectors as columns, ``v[:, i]`` for ``w[i]``.
    """
    m = a_in.shape[0]
    a = a_in.copy()
    v = np.eye(m)
    scale = 0.0
    for i in range(m):
        for j in range(m):
            scale += a[i, j] * a[i, j]
    for _sweep in range(60):
        off = 0.0
        for i in range(m - 1):
            for j in range(i + 1, m):
                off += a[i, j] * a[i, j]
        if off <= 1e-32 * scale or off == 0.0:
            break
        for p in range(m - 1):
            for q in range(p + 1, m):
                apq = a[p, q]
                if apq == 0.0:
                    continue
                theta = (a[q, q] - a[p, p]) / (2.0 * apq)
                t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / np.sqrt(t * t + 1.0)
                s = t * c
                for k in range(m):
                    akp = a[k, p]
                    akq = a[k, q]
                    a[k, p] = c * akp - s * akq
                    a[k, q] = s * akp + c * akq
                for k in range(m):
                    apk = a[p, k]
                    aqk = a[q, k]
                    a[p, k] = c * apk - s * aqk
                    a[q, k] = s * apk + c * aqk
                for k in range(m):
                    vkp = v[k, p]
                    vkq = v[k, q]
                    v[k, p] = c * vkp - s * vkq
                    v[k, q] = s * vkp + c * vkq
    w = np.empty(m)
    for i in range(m):
        w[i] = a[i, i]
    order = np.argsort(w)
    return w[order], v[:, order]


@njit(cache=True)
def cholesky(a, rel_tol):
    """Lower Cholesky factor of a symmetric positive definite matrix.

    Parameters
    ----------
    a : ndarray, shape (m, m)
    rel_tol : float
        A pivot below ``rel_tol * max(diag(a))`` counts as rank deficient.

    Returns
    -------
    l : ndarray, shape (m, m)
        Lower-triangular factor (undefined when ``ok`` is False).
    ok : bool
        False when the matrix is not numerically positive definite.
    """
    m = a.shape[0]
    l = np.zeros((m, m))
    dmax = 0.0
    for i in range(m):
        dmax = max(dmax, a[i, i])
    if not dmax > 0.0:
        return l, False
    floor = rel_tol * dmax
    for j in range(m):
        s = a[j, j]
        for k in range(j):
            s -= l[j, k] * l[j, k]
        if not s > floor:
            return l, False
        ljj = np.sqrt(s)
        l[j, j] = ljj
        for i in range(j + 1, m):
            s = a[i, j]
            for k in range(j):
                s -= l[i, k] * l[j, k]
            l[i, j] = s / ljj
    return l, True


@njit(cache=True)
def solve_lower(l, b):
    """Solve ``l x = b`` for lower-triangular ``l``; ``b`` shape (m,) or (m, r)."""
    m = l.shape[0]
    x = b.copy()
    for i in range(m):
        for k in range(i):
            x[i] -= l[i, k] * x[k]
        x[i] /= l[i, i]
    return x


@njit(cache=True)
def solve_upper_t(l, b):
    """Solve ``l.T x = b`` for lower-triangular ``l``; ``b`` shape (m,)."""
    m = l.shape[0]
    x = b.copy()
    for i in range(m - 1, -1, -1):
        for k in range(i + 1, m):
            x[i] -= l[k, i] * x[k]
        x[i] /= l[i, i]
    return x


@njit(cache=True)
def generalized_smallest(mat, metric, rel_tol):
    """Eigenvector of the smallest eigenvalue of ``mat v = lam metric v``.

    Reduced to a standard problem with the Cholesky factor of ``metric`` (Taubin's method).

    Parameters
    ----------
    mat : ndarray, shape (m, m)
        Symmetric positive semi-definite.
    metric : ndarray, shape (m, m)
        Symmetric positive semi-definite (ridged slightly before factorising).
    rel_tol : float
        Pivot tolerance of the Cholesky factorisation.

    Returns
    -------
    vec : ndarray, shape (m,)
        The eigenvector, normalised so that ``vec' metric vec = 1``.
    lam : float
        The smallest eigenvalue.
    ok : bool
        False when ``metric`` is not numerically positive definite.
    """
    m = mat.shape[0]
    # A tiny ridge keeps the metric definite where a monomial's gradient vanishes on every point
    # (z^2 on an exact plane z = 0); scaled by the trace so it is rotation invariant.
    ridged = metric.copy()
    tr = 0.0
    for i in range(m):
        tr += metric[i, i]
    for i in range(m):
        ridged[i, i] += 1e-10 * tr / m
    l, ok = cholesky(ridged, rel_tol)
    if not ok:
        return np.zeros(m), 0.0, False
    # c = L^-1 mat L^-T, formed column by column.
    tmp = solve_lower(l, mat)          # L^-1 mat
    c = solve_lower(l, tmp.T.copy())   # L^-1 (L^-1 mat)^T = L^-1 mat L^-T (mat symmetric)
    for i in range(m):
        for j in range(i + 1, m):
            s = 0.5 * (c[i, j] + c[j, i])
            c[i, j] = s
            c[j, i] = s
    y, lam = smallest_eigvec(c, 100, 1e-13)
    return solve_upper_t(l, y), lam, True


@njit(cache=True)
def smallest_eigvec(c, max_iter, tol):
    """Eigenvector of the smallest eigenvalue of a symmetric PSD matrix by inverse iteration.

    Only this eigenvector is needed by the quadric fits, and inverse iteration with a tiny shift
    needs a few triangular solves where a full decomposition needs thousands of rotations.
    Falls back to :func:`jacobi_eigh` when the iteration does not settle.

    Parameters
    ----------
    c : ndarray, shape (m, m)
        Symmetric positive semi-definite matrix.
    max_iter : int
        Iteration budget before the fallback.
    tol : float
        Convergence threshold on the eigen-residual |C y - lam y|, relative to trace(C).

    Returns
    -------
    y : ndarray, shape (m,)
        Unit eigenvector.
    lam : float
        Its eigenvalue (Rayleigh quotient).
    """
    m = c.shape[0]
    tr = 0.0
    for i in range(m):
        tr += c[i, i]
    shifted = c.copy()
    shift = 1e-11 * tr / m + 1e-300
    for i in range(m):
        shifted[i, i] += shift
    l, ok = cholesky(shifted, 1e-300)
    if ok:
        y = np.ones(m) / np.sqrt(m)
        # Stop on the eigen-residual, not on the step: with close eigenvalues the steps are
        # small long before y is an eigenvector.
        target = tol * tr + 1e-300
        for _ in range(max_iter):
            z = solve_upper_t(l, solve_lower(l, y))
            norm = np.sqrt(np.sum(z * z))
            if not norm > 0.0:
                break
            y = z / norm
            cy = c @ y
            lam = np.sum(y * cy)
            if np.sqrt(np.sum((cy - lam * y) ** 2)) <= target:
                return y, lam
    w, v = jacobi_eigh(c)
    return v[:, 0].copy(), w[0]
