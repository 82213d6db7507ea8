"""Per-point quadric fits over CSR neighborhoods, parallel over query points (numba).

Every query point is independent, so the results do not depend on the number of threads.
Coordinates are translated to the query point p and divided by the RMS neighbor distance before
fitting (DESIGN.md 4.5); curvature is scaled back at the end.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .linalg import (
    cholesky,
    eigh3,
    generalized_smallest,
    smallest_eigvec,
    solve_lower,
    solve_upper_t,
)
from .moments import gradient_metric, moments4, scatter_matrix
from .quadric import (
    DEGENERATE,
    NO_FOOT,
    NON_FINITE,
    OK,
    TOO_FEW,
    clear_outputs,
    foot_point,
    gradient_at,
    sampson_rms,
    shape_operator,
    store_outputs,
)

FIT_IMPLICIT = 0
FIT_MONGE = 1
# The implicit quadric where it fits the neighborhood (clean data, exact on quadrics), else
# the height function (noisy data, where the implicit quadric bends to fit the noise).
FIT_ADAPTIVE = 2
SOLVER_TAUBIN = 0
SOLVER_ALGEBRAIC = 1
SQRT2 = np.sqrt(2.0)
# Fewest fitted points (p included) that determine each model: 9 Taubin unknowns up to scale,
# 6 Monge coefficients.
MIN_POINTS_IMPLICIT = 9
MIN_POINTS_MONGE = 6
# A foot point farther than this many RMS neighbor distances means the fit missed p.
MAX_FOOT_DIST = 2.0


@njit(cache=True)
def gather_local(points, q, nbr, include_self):
    """Neighbors (and optionally p) relative to p = points[q], scaled to unit RMS distance.

    Returns
    -------
    xs : ndarray, shape (m, 3)
        Scaled local coordinates; p itself, when included, is row 0 at the origin.
    scale : float
        RMS distance of the neighbors to p (0 when they all coincide with p).
    """
    k = nbr.shape[0]
    off = 1 if include_self else 0
    xs = np.zeros((k + off, 3))
    p = points[q]
    ss = 0.0
    for i in range(k):
        for d in range(3):
            v = points[nbr[i], d] - p[d]
            xs[i + off, d] = v
            ss += v * v
    scale = np.sqrt(ss / k) if k > 0 else 0.0
    if scale > 0.0:
        xs /= scale
    return xs, scale


@njit(cache=True)
def quadric_from_coeffs(v):
    """Split 10 coefficients of the rotation-invariant monomial basis into A (3, 3), b (3,), c.

    Basis: x^2, y^2, z^2, sqrt2 xy, sqrt2 yz, sqrt2 xz, x, y, z, 1; with the sqrt2 weights the
    coefficient norm equals |A|_F^2 + |b|^2 + c^2, which rotations leave unchanged.
    """
    a = np.empty((3, 3))
    a[0, 0] = v[0]
    a[1, 1] = v[1]
    a[2, 2] = v[2]
    a[0, 1] = a[1, 0] = v[3] / SQRT2
    a[1, 2] = a[2, 1] = v[4] / SQRT2
    a[0, 2] = a[2, 0] = v[5] / SQRT2
    b = np.array([v[6], v[7], v[8]])
    return a, b, v[9]


@njit(cache=True)
def fit_implicit(xs, solver):
    """General quadric through local points, Taubin or algebraic.

    Parameters
    ----------
    xs : ndarray, shape (m, 3)
        Scaled local coordinates.
    solver : int
        SOLVER_TAUBIN or SOLVER_ALGEBRAIC.

    Returns
    -------
    a, b, c
        The quadric F = x'Ax + b'x + c.
    ok : bool
        False when the problem is rank deficient.
    """
    m = xs.shape[0]
    coeffs = np.zeros(10)
    mom = moments4(xs)
    scatter = scatter_matrix(mom) / m
    if solver == SOLVER_TAUBIN:
        # Centring the monomials eliminates the constant (its gradient is zero, which makes the
        # full 10x10 Taubin metric singular) and leaves a 9x9 generalized eigenproblem.
        mean = scatter[9, :9].copy()  # the constant's row holds the monomial means
        centred = scatter[:9, :9] - np.outer(mean, mean)
        vec, _lam, ok = generalized_smallest(centred, gradient_metric(mom) / m, 1e-12)
        if not ok:
            return np.zeros((3, 3)), np.zeros(3), 0.0, False
        coeffs[:9] = vec
        coeffs[9] = -np.sum(mean * vec)
    else:
        vec, _lam = smallest_eigvec(scatter, 20, 1e-13)
        coeffs[:] = vec
    a, b, c = quadric_from_coeffs(coeffs)
    return a, b, c, True


@njit(cache=True)
def principal_axes(xs):
    """Covariance eigen-decomposition of local points.

    Parameters
    ----------
    xs : ndarray, shape (m, 3)

    Returns
    -------
    w : ndarray, shape (3,)
        Variances along the axes, ascending.
    v : ndarray, shape (3, 3)
        Unit axes as columns (the last is the direction of largest spread).
    """
    m = xs.shape[0]
    centroid = np.zeros(3)
    for i in range(m):
        centroid += xs[i]
    centroid /= m
    cov = np.zeros((3, 3))
    for i in range(m):
        d0 = xs[i, 0] - centroid[0]
        d1 = xs[i, 1] - centroid[1]
        d2 = xs[i, 2] - centroid[2]
        cov[0, 0] += d0 * d0
        cov[0, 1] += d0 * d1
        cov[0, 2] += d0 * d2
        cov[1, 1] += d1 * d1
        cov[1, 2] += d1 * d2
        cov[2, 2] += d2 * d2
    cov[1, 0] = cov[0, 1]
    cov[2, 0] = cov[0, 2]
    cov[2, 1] = cov[1, 2]
    return eigh3(cov / m)


@njit(cache=True)
def spans_surface(w):
    """Whether the points spread in two directions (not all on a line or a point)."""
    return w[1] > 1e-10 * w[2]


@njit(cache=True)
def fit_monge(xs, v, circular=0):
    """Height function h(u, v) = a u^2 + b uv + c v^2 + d u + e v + f in a PCA frame.

    Returns the quadric F = h(u, v) + t w^2 - w in local coordinates (rotated back to the input
    axes), t = 0 unless ``circular``.

    A height quadric over a patch of a sphere or cylinder of curvature k is biased by the
    fourth-order term of the height (k^3 r^4 / 8): on 48-point patches of a corner sphere of
    6 spacings' radius it reads k2 about 10 % high. ``circular`` rounds of refitting fix it:
    with t = k_d / 2 (k_d the dominant curvature of the last fit) the fit is made to
    w - t q(u, v)^2, q the last fitted height, so that F = 0 is exactly that sphere or
    cylinder (its w = q + t w^2, w^2 = q^2 to fourth order) and F's curvature at the
    patch is read unchanged (the w^2 term is of second order in w).

    Parameters
    ----------
    xs : ndarray, shape (m, 3)
        Scaled local coordinates.
    v : ndarray, shape (3, 3)
        Principal axes from :func:`principal_axes` (columns, ascending spread).
    circular : int
        Rounds of the circular correction (0: the plain height quadric).

    Returns
    -------
    a, b, c
        The quadric F = x'Ax + b'x + c in the input axes.
    ok : bool
        False when the normal equations are singular.
    """
    m = xs.shape[0]
    # Frame columns: u, v (largest spreads), n (smallest), right-handed.
    frame = np.empty((3, 3))
    frame[:, 0] = v[:, 2]
    frame[:, 1] = v[:, 1]
    frame[:, 2] = np.cross(v[:, 2], v[:, 1])
    # The normal equations of the rows (u^2, uv, v^2, u, v, 1), summed in scalars (kept in
    # registers; an array's entries are stored back at every point).
    f00, f01, f02 = frame[0, 0], frame[0, 1], frame[0, 2]
    f10, f11, f12 = frame[1, 0], frame[1, 1], frame[1, 2]
    f20, f21, f22 = frame[2, 0], frame[2, 1], frame[2, 2]
    s00 = s01 = s02 = s03 = s04 = s05 = 0.0
    s11 = s12 = s13 = s14 = s15 = 0.0
    s22 = s23 = s24 = s25 = 0.0
    s33 = s34 = s35 = s44 = s45 = s55 = 0.0
    b0 = b1 = b2 = b3 = b4 = b5 = 0.0
    for i in range(m):
        x0, x1, x2 = xs[i, 0], xs[i, 1], xs[i, 2]
        u = x0 * f00 + x1 * f10 + x2 * f20
        vv = x0 * f01 + x1 * f11 + x2 * f21
        h = x0 * f02 + x1 * f12 + x2 * f22
        r0, r1, r2, r3, r4 = u * u, u * vv, vv * vv, u, vv
        b0 += r0 * h
        s00 += r0 * r0
        s01 += r0 * r1
        s02 += r0 * r2
        s03 += r0 * r3
        s04 += r0 * r4
        s05 += r0
        b1 += r1 * h
        s11 += r1 * r1
        s12 += r1 * r2
        s13 += r1 * r3
        s14 += r1 * r4
        s15 += r1
        b2 += r2 * h
        s22 += r2 * r2
        s23 += r2 * r3
        s24 += r2 * r4
        s25 += r2
        b3 += r3 * h
        s33 += r3 * r3
        s34 += r3 * r4
        s35 += r3
        b4 += r4 * h
        s44 += r4 * r4
        s45 += r4
        b5 += h
        s55 += 1.0
    ata = np.empty((6, 6))
    atb = np.empty(6)
    sums = (s00, s01, s02, s03, s04, s05, s11, s12, s13, s14, s15, s22, s23, s24, s25,
            s33, s34, s35, s44, s45, s55)
    t = 0
    for r in range(6):
        for c in range(r, 6):
            ata[r, c] = ata[c, r] = sums[t]
            t += 1
    atb[0], atb[1], atb[2], atb[3], atb[4], atb[5] = b0, b1, b2, b3, b4, b5
    l, ok = cholesky(ata, 1e-13)
    if not ok:
        return np.zeros((3, 3)), np.zeros(3), 0.0, False
    coef = solve_upper_t(l, solve_lower(l, atb))
    t = 0.0
    for _ in range(circular):
        # Dominant curvature of the fitted height's Hessian.
        h11, h12, h22 = 2.0 * coef[0], coef[1], 2.0 * coef[2]
        mid = 0.5 * (h11 + h22)
        rad = np.sqrt(0.25 * (h11 - h22) ** 2 + h12 * h12)
        kd = mid + rad if abs(mid + rad) >= abs(mid - rad) else mid - rad
        t = 0.5 * kd
        atb[:] = 0.0
        for i in range(m):
            u = xs[i, 0] * frame[0, 0] + xs[i, 1] * frame[1, 0] + xs[i, 2] * frame[2, 0]
            vv = xs[i, 0] * frame[0, 1] + xs[i, 1] * frame[1, 1] + xs[i, 2] * frame[2, 1]
            h = xs[i, 0] * frame[0, 2] + xs[i, 1] * frame[1, 2] + xs[i, 2] * frame[2, 2]
            q = coef[0] * u * u + coef[1] * u * vv + coef[2] * vv * vv + coef[3] * u \
                + coef[4] * vv + coef[5]
            r = h - t * q * q
            atb[0] += u * u * r
            atb[1] += u * vv * r
            atb[2] += vv * vv * r
            atb[3] += u * r
            atb[4] += vv * r
            atb[5] += r
        coef = solve_upper_t(l, solve_lower(l, atb))
    # F = h(u, v) + t w^2 - w in frame coordinates, then x = frame @ (u, v, w) back to input axes.
    a_loc = np.zeros((3, 3))
    a_loc[0, 0] = coef[0]
    a_loc[1, 1] = coef[2]
    a_loc[0, 1] = a_loc[1, 0] = 0.5 * coef[1]
    a_loc[2, 2] = t
    b_loc = np.array([coef[3], coef[4], -1.0])
    # frame @ a_loc @ frame.T and frame @ b_loc written out: numba's @ calls BLAS, whose
    # call overhead is most of the time of a 3x3 product (this runs once per rung fit).
    tmp = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            tmp[i, j] = frame[i, 0] * a_loc[0, j] + frame[i, 1] * a_loc[1, j] \
                + frame[i, 2] * a_loc[2, j]
    a = np.empty((3, 3))
    b = np.empty(3)
    for i in range(3):
        for j in range(3):
            a[i, j] = tmp[i, 0] * frame[j, 0] + tmp[i, 1] * frame[j, 1] + tmp[i, 2] * frame[j, 2]
        b[i] = frame[i, 0] * b_loc[0] + frame[i, 1] * b_loc[1] + frame[i, 2] * b_loc[2]
    return a, b, coef[5], True


@njit(parallel=True, cache=True)
def fit_batch(points, query, indptr, indices, fit, solver, include_self, clean_residual,
              k1, k2, normals, dir1, dir2, residual, status):
    """Fit every query point's neighborhood and write curvature into the output arrays.

    Parameters
    ----------
    points : ndarray, shape (n, 3), float64
        The cloud.
    query : ndarray, shape (m,), int64
        Query point indices.
    indptr : ndarray, shape (m + 1,), int64
    indices : ndarray, shape (nnz,), int32 or int64
        Neighborhoods of the query points (CSR, query point not listed).
    fit : int
        FIT_IMPLICIT, FIT_MONGE or FIT_ADAPTIVE.
    solver : int
        SOLVER_TAUBIN or SOLVER_ALGEBRAIC (implicit only).
    include_self : bool
        Whether p itself takes part in the fit.
    clean_residual : float
        FIT_ADAPTIVE only: the implicit quadric is kept where its RMS residual is at most
        this fraction of the RMS neighbor distance (and it has a foot point); elsewhere the
        height function is fitted instead.
    k1, k2, residual : ndarray, shape (m,), float64
        Outputs, NaN where the status is not OK.
    normals, dir1, dir2 : ndarray, shape (m, 3), float64
        Outputs: unnormalised-sign unit normal (sign fixed later by orientation) and directions.
    status : ndarray, shape (m,), int8
        Output status codes.
    """
    m = query.shape[0]
    need = MIN_POINTS_IMPLICIT if fit == FIT_IMPLICIT else MIN_POINTS_MONGE
    for j in prange(m):
        clear_outputs(j, k1, k2, residual, normals, dir1, dir2)
        nbr = indices[indptr[j]:indptr[j + 1]]
        count = nbr.shape[0] + (1 if include_self else 0)
        if count < need:
            status[j] = TOO_FEW
            continue
        xs, scale = gather_local(points, query[j], nbr, include_self)
        if not scale > 0.0:
            status[j] = DEGENERATE
            continue
        w, axes = principal_axes(xs)
        if not spans_surface(w):  # coincident or collinear: no surface to fit
            status[j] = DEGENERATE
            continue
        a = np.zeros((3, 3))
        b = np.zeros(3)
        c = 0.0
        x0 = np.zeros(3)
        ok = False
        found = False
        rel = np.inf
        if fit != FIT_MONGE and count >= MIN_POINTS_IMPLICIT:
            a, b, c, ok = fit_implicit(xs, solver)
            if ok:
                x0, found = foot_point(a, b, c, MAX_FOOT_DIST)
                rel = sampson_rms(a, b, c, xs)
        if fit == FIT_MONGE or (fit == FIT_ADAPTIVE and not (found and rel <= clean_residual)):
            a, b, c, ok = fit_monge(xs, axes)
            found = False
            if ok:
                x0, found = foot_point(a, b, c, MAX_FOOT_DIST)
                rel = sampson_rms(a, b, c, xs)
        if not ok:
            status[j] = DEGENERATE
            continue
        if not found:
            status[j] = NO_FOOT
            continue
        g = gradient_at(a, b, x0)
        c1, c2, n, d1, d2 = shape_operator(g, 2.0 * a)
        res = rel * scale
        c1 /= scale
        c2 /= scale
        if not store_outputs(j, c1, c2, n, d1, d2, k1, k2, normals, dir1, dir2):
            status[j] = NON_FINITE
            continue
        residual[j] = res
        status[j] = OK
