"""Small dense linear algebra for per-point fits, written for numba.

LAPACK calls from numba allocate and carry call overhead that dominates for 3x3..10x10 systems,
and they raise on failure; these routines return a success flag instead so a bad point becomes a
status code, never an exception.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# Reassociation lets LLVM split a sum over SIMD lanes (the Gram matrices of the fits are most of
# their time); no-NaN assumptions stay off, so NaN still propagates and callers' checks hold.
SIMD_SUM = {"reassoc", "contract", "nsz"}


@njit(fastmath=SIMD_SUM, cache=True)
def dot(a, b, m):
    """``sum(a[:m] * b[:m])`` of two contiguous vectors, summed in SIMD lanes.

    Parameters
    ----------
    a, b : ndarray, shape (>= m,)
    m : int

    Returns
    -------
    float
    """
    s = 0.0
    for i in range(m):
        s += a[i] * b[i]
    return s


@njit(fastmath=SIMD_SUM, cache=True)
def total(a, m):
    """``sum(a[:m])`` of a contiguous vector, summed in SIMD lanes."""
    s = 0.0
    for i in range(m):
        s += a[i]
    return s


@njit(cache=True, inline="always")
def _jacobi_sweeps(a, v, m):
    """Cyclic Jacobi rotations of the symmetric ``a`` (m, m) in place until its off-diagonal
    part vanishes; the rotations are accumulated into ``v`` (the identity on entry). Inlined,
    so a caller with a fixed m gets the loops unrolled."""
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
    _jacobi_sweeps(a, v, m)
    w = np.empty(m)
    for i in range(m):
        w[i] = a[i, i]
    order = np.argsort(w)
    return w[order], v[:, order]


@njit(cache=True)
def jacobi3(a, v):
    """:func:`jacobi_eigh`'s rotations on a symmetric 3x3 matrix, in place and unsorted.

    The same operations in the same order as ``jacobi_eigh`` (so the same bits), with the size
    fixed at 3 so that the loops unroll and nothing is allocated: PCA normals run one per
    point, and there this was 70 % of their time.

    Parameters
    ----------
    a : ndarray, shape (3, 3)
        Symmetric matrix; overwritten, its diagonal ends as the eigenvalues.
    v : ndarray, shape (3, 3)
        Output: unit eigenvectors as columns, ``v[:, i]`` for ``a[i, i]``.

    Returns
    -------
    i0, i1, i2 : int
        Column indices in ascending order of the eigenvalues (a stable sort, as the
        ``argsort`` of ``jacobi_eigh``).
    """
    for i in range(3):
        for j in range(3):
            v[i, j] = 1.0 if i == j else 0.0
    _jacobi_sweeps(a, v, 3)
    # Insertion sort of three, stable on ties.
    i0, i1, i2 = 0, 1, 2
    if a[1, 1] < a[0, 0]:
        i0, i1 = 1, 0
    if a[2, 2] < a[i1, i1]:
        i1, i2 = 2, i1
        if a[2, 2] < a[i0, i0]:
            i0, i1 = 2, i0
    return i0, i1, i2


@njit(cache=True)
def eigh3(a_in):
    """:func:`jacobi_eigh` of a symmetric 3x3 matrix, bit for bit, at a third of its time
    (:func:`jacobi3`)."""
    a = a_in.copy()
    v = np.empty((3, 3))
    order = jacobi3(a, v)
    w = np.empty(3)
    vs = np.empty((3, 3))
    for c in range(3):
        w[c] = a[order[c], order[c]]
        for r in range(3):
            vs[r, c] = v[r, order[c]]
    return w, vs


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
    """Solve ``l x = b`` for lower-triangular ``l`` (m, m) and a vector ``b`` (m,)."""
    m = l.shape[0]
    x = b.copy()
    for i in range(m):
        acc = x[i]
        for k in range(i):
            acc -= l[i, k] * x[k]
        x[i] = acc / l[i, i]
    return x


@njit(cache=True)
def solve_spd(a, b, rel_tol):
    """``a^-1 b`` for a symmetric positive definite ``a`` (m, m) and ``b`` (m,), and False
    where ``a`` is numerically singular (:func:`cholesky`'s ``rel_tol``; ``b`` is returned
    then, the solution being undefined)."""
    low, ok = cholesky(a, rel_tol)
    if not ok:
        return b, False
    return solve_upper_t(low, solve_lower(low, b)), True


@njit(cache=True)
def congruence_inverse(l, mat):
    """``L^-1 mat L^-T`` for lower-triangular ``l`` and symmetric ``mat``, both (m, m).

    Written with scalar loops: slicing rows here would allocate a temporary per update.
    """
    m = l.shape[0]
    t = np.empty((m, m))
    # t = L^-1 mat, column by column (forward substitution).
    for j in range(m):
        for i in range(m):
            acc = mat[i, j]
            for k in range(i):
                acc -= l[i, k] * t[k, j]
            t[i, j] = acc / l[i, i]
    # out = L^-1 t^T; symmetric, so only the lower triangle is solved and mirrored.
    out = np.empty((m, m))
    for j in range(m):
        for i in range(m):
            acc = t[j, i]
            for k in range(i):
                acc -= l[i, k] * out[k, j]
            out[i, j] = acc / l[i, i]
    for i in range(m):
        for j in range(i + 1, m):
            v = 0.5 * (out[i, j] + out[j, i])
            out[i, j] = v
            out[j, i] = v
    return out


@njit(cache=True)
def solve_upper_t(l, b):
    """Solve ``l.T x = b`` for lower-triangular ``l``; ``b`` shape (m,)."""
    m = l.shape[0]
    x = b.copy()
    for i in range(m - 1, -1, -1):
        acc = x[i]
        for k in range(i + 1, m):
            acc -= l[k, i] * x[k]
        x[i] = acc / l[i, i]
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
    c = congruence_inverse(l, mat)
    y, lam = smallest_eigvec(c, 20, 1e-13)
    return solve_upper_t(l, y), lam, True


@njit(cache=True)
def solve_shifted(c, shift, y):
    """Solve (c - shift I) z = y by LU with partial pivoting; a zero pivot is nudged.

    Parameters
    ----------
    c : ndarray, shape (m, m)
    shift : float
    y : ndarray, shape (m,)

    Returns
    -------
    ndarray, shape (m,)
        The solution. Near an eigenvalue it is large along the eigenvector, which is what
        inverse iteration wants, so an exactly singular pivot is replaced by a tiny one.
    """
    m = c.shape[0]
    a = c.copy()
    for i in range(m):
        a[i, i] -= shift
    x = y.copy()
    tiny = 1e-300
    for i in range(m):
        for k in range(i):
            tiny = max(tiny, abs(a[i, k]))
    tiny *= 1e-15
    for col in range(m):
        piv = col
        best = abs(a[col, col])
        for r in range(col + 1, m):
            if abs(a[r, col]) > best:
                best = abs(a[r, col])
                piv = r
        if piv != col:
            for k in range(m):
                a[col, k], a[piv, k] = a[piv, k], a[col, k]
            x[col], x[piv] = x[piv], x[col]
        if abs(a[col, col]) < tiny:
            a[col, col] = tiny
        for r in range(col + 1, m):
            f = a[r, col] / a[col, col]
            if f != 0.0:
                for k in range(col, m):
                    a[r, k] -= f * a[col, k]
                x[r] -= f * x[col]
    for i in range(m - 1, -1, -1):
        acc = x[i]
        for k in range(i + 1, m):
            acc -= a[i, k] * x[k]
        x[i] = acc / a[i, i]
    return x


@njit(cache=True)
def smallest_eigvec(c, max_iter, tol):
    """Eigenvector of the smallest eigenvalue of a symmetric PSD matrix.

    Only this eigenvector is needed by the quadric fits. A few steps of inverse iteration steer
    towards it, Rayleigh quotient iteration then converges cubically, and a Cholesky test of
    c - (lam - delta) I certifies that no eigenvalue lies below the one found. Falls back to
    :func:`jacobi_eigh` when the iteration does not settle or the certificate fails.

    Parameters
    ----------
    c : ndarray, shape (m, m)
        Symmetric positive semi-definite matrix.
    max_iter : int
        Rayleigh iterations before the fallback.
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
    target = tol * tr + 1e-300
    y = np.ones(m) / np.sqrt(m)
    # Unshifted steps until the Rayleigh quotient settles, so that the cubic phase below starts
    # in the basin of the smallest eigenvalue rather than of the next one.
    prev = np.inf
    for _ in range(12):
        z = solve_shifted(c, 0.0, y)
        y = z / np.sqrt(np.sum(z * z))
        lam = np.sum(y * (c @ y))
        if prev - lam <= 0.02 * lam:
            break
        prev = lam
    if np.all(np.isfinite(y)):
        for _ in range(max_iter):
            cy = c @ y
            lam = np.sum(y * cy)
            res = np.sqrt(np.sum((cy - lam * y) ** 2))
            if res <= target:
                delta = 1e-10 * tr + 2.0 * res + 1e-300
                shifted = c.copy()
                for i in range(m):
                    shifted[i, i] -= lam - delta
                _l, smallest = cholesky(shifted, 0.0)
                if smallest:
                    return y, lam
                break
            z = solve_shifted(c, lam, y)
            norm = np.sqrt(np.sum(z * z))
            if not (norm > 0.0 and np.isfinite(norm)):
                break
            y = z / norm
    w, v = jacobi_eigh(c)
    return v[:, 0].copy(), w[0]
