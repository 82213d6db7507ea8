"""Normal-constrained quadric: the quadric whose gradient field best matches estimated normals.

Around a centre point p, with neighbors at scaled positions x_i = (q_i - p) / h and unit normals
n_i (flipped to agree with p's), find the quadric F(x) = x'ax + b'x + c whose gradient
g(x) = 2ax + b is parallel to every n_i: minimise sum |(I - n_i n_i') g(x_i)|^2 subject to
sum n_i . g(x_i) = m (which fixes F's scale). That is one 9x9 linear solve; the offset c then
places F = 0 through the points (weighted by 1 / |g|^2, a first-order distance).

Why: the unit normal of any quadric is g / |g| with g linear in position, so this model is exact
on spheres, cylinders and ellipsoids at every neighborhood size, including the tips of an
elongated ellipsoid where the normal turns by more than a radian within the neighborhood and a
polynomial normal field (:mod:`curvature.fitting.normal_field`) flattens the curvature peak. It
has 9 unknowns against that field's 20, so it averages noise better; its weakness is a surface
that is not a quadric at the neighborhood's scale (a torus's inner side over hundreds of
points), which the caller detects from :func:`regress_normal_quadric`'s misfit
(docs/accuracy.md section 8 has the measurements).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .linalg import cholesky, solve_lower, solve_upper_t
from .quadric import DEGENERATE, NO_FOOT, OK, TOO_FEW, foot_point, shape_operator

# a00, a11, a22, a01, a02, a12, b0, b1, b2 and the offset c.
N_QUAD = 10
N_UNKNOWNS = 9
MIN_POINTS_NQ = 12
# Relative ridge on the normal matrix: a plane (all normals equal) leaves a two-dimensional
# null space (b along n, a = n n'); the ridge picks its smallest member, which has no curvature.
RIDGE = 1e-12


# g(x) = 2ax + b is linear in the 9 unknowns theta; each of its 3 components involves 4 of
# them: g_d = sum_j vals[d, j] * theta[ROW_COLS[d, j]], vals from _design_values(x).
ROW_COLS = np.array([[0, 3, 4, 6], [1, 3, 5, 7], [2, 4, 5, 8]], np.int64)


@njit(cache=True)
def _design_values(x0, x1, x2, vals):
    """Nonzero entries (3, 4) of the rows of g(x), in the column order of ``ROW_COLS``."""
    vals[0, 0] = 2.0 * x0
    vals[0, 1] = 2.0 * x1
    vals[0, 2] = 2.0 * x2
    vals[1, 0] = 2.0 * x1
    vals[1, 1] = 2.0 * x0
    vals[1, 2] = 2.0 * x2
    vals[2, 0] = 2.0 * x2
    vals[2, 1] = 2.0 * x0
    vals[2, 2] = 2.0 * x1
    for d in range(3):
        vals[d, 3] = 1.0


@njit(cache=True)
def quad_matrix(quad):
    """Symmetric ``a`` (3, 3) and ``b`` (3,) of packed coefficients ``quad`` (N_QUAD,)."""
    a = np.empty((3, 3))
    a[0, 0] = quad[0]
    a[1, 1] = quad[1]
    a[2, 2] = quad[2]
    a[0, 1] = a[1, 0] = quad[3]
    a[0, 2] = a[2, 0] = quad[4]
    a[1, 2] = a[2, 1] = quad[5]
    return a, quad[6:9].copy()


@njit(cache=True)
def _gradient(quad, x0, x1, x2):
    """g(x) = 2ax + b of packed coefficients, as three scalars (no allocation)."""
    g0 = 2.0 * (quad[0] * x0 + quad[3] * x1 + quad[4] * x2) + quad[6]
    g1 = 2.0 * (quad[3] * x0 + quad[1] * x1 + quad[5] * x2) + quad[7]
    g2 = 2.0 * (quad[4] * x0 + quad[5] * x1 + quad[2] * x2) + quad[8]
    return g0, g1, g2


@njit(cache=True)
def regress_normal_quadric(points, field, p, nbr, include_self, quad):
    """Fit the normal-constrained quadric around ``p`` (module docstring).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    field : ndarray, shape (n, 3)
        Unit normals of every point (sign arbitrary, NaN where unknown).
    p : int
        The fit's centre: the origin of the scaled coordinates and the normal sign reference.
    nbr : ndarray, shape (k,)
        Neighbors of p (p itself not listed).
    include_self : bool
        Whether p takes part in the fit.
    quad : ndarray, shape (N_QUAD,)
        Output: a00, a11, a22, a01, a02, a12, b0, b1, b2, c of F in the coordinates
        ``(x - points[p]) / h``; g = 2ax + b points along p's normal.

    Returns
    -------
    status : int
        OK, TOO_FEW or DEGENERATE.
    h : float
        RMS distance of the fitted points from p (the coordinates' unit).
    misfit : float
        Mean squared sine of the angle between each fitted normal and the model's gradient.
    distance : float
        RMS first-order distance |F| / |g| of the fitted points to F = 0, in input units.
    """
    m = nbr.shape[0] + (1 if include_self else 0)
    n_p = field[p]
    if m < MIN_POINTS_NQ:
        return TOO_FEW, 0.0, np.nan, np.nan
    if not np.all(np.isfinite(n_p)):
        return DEGENERATE, 0.0, np.nan, np.nan
    # Offsets from p and normals flipped to agree with p's, of the points with a known normal.
    xs = np.empty((m, 3))
    ns = np.empty((m, 3))
    used = 0
    ss = 0.0
    for i in range(m):
        q = p if (include_self and i == 0) else nbr[i - (1 if include_self else 0)]
        nx, ny, nz = field[q, 0], field[q, 1], field[q, 2]
        if not (np.isfinite(nx) and np.isfinite(ny) and np.isfinite(nz)):
            continue
        s = 1.0 if nx * n_p[0] + ny * n_p[1] + nz * n_p[2] >= 0.0 else -1.0
        for d in range(3):
            xs[used, d] = points[q, d] - points[p, d]
            ss += xs[used, d] * xs[used, d]
        ns[used, 0] = s * nx
        ns[used, 1] = s * ny
        ns[used, 2] = s * nz
        used += 1
    if used < MIN_POINTS_NQ:
        return TOO_FEW, 0.0, np.nan, np.nan
    h = np.sqrt(ss / used)
    if not h > 0.0:
        return DEGENERATE, 0.0, np.nan, np.nan
    xs = xs[:used] / h
    # |(I - nn') X theta|^2 = theta' (X'X - vv') theta with v = X'n, summed over the points;
    # X'X is accumulated from the rows' 4 nonzeros (full matrix), vv' on the upper triangle.
    xtx = np.zeros((N_UNKNOWNS, N_UNKNOWNS))
    mat = np.zeros((N_UNKNOWNS, N_UNKNOWNS))
    rhs = np.zeros(N_UNKNOWNS)
    vals = np.empty((3, 4))
    v = np.empty(N_UNKNOWNS)
    for i in range(used):
        _design_values(xs[i, 0], xs[i, 1], xs[i, 2], vals)
        v[:] = 0.0
        for d in range(3):
            for a in range(4):
                ca = ROW_COLS[d, a]
                v[ca] += ns[i, d] * vals[d, a]
                for b in range(4):
                    xtx[ca, ROW_COLS[d, b]] += vals[d, a] * vals[d, b]
        for r in range(N_UNKNOWNS):
            rhs[r] += v[r]
            for c in range(r, N_UNKNOWNS):
                mat[r, c] -= v[r] * v[c]
    trace = 0.0
    for r in range(N_UNKNOWNS):
        for c in range(r, N_UNKNOWNS):
            mat[r, c] += xtx[r, c]
            mat[c, r] = mat[r, c]
        trace += mat[r, r]
    for r in range(N_UNKNOWNS):
        mat[r, r] += RIDGE * trace
    low, good = cholesky(mat, 1e-13)
    if not good:
        return DEGENERATE, h, np.nan, np.nan
    z = solve_upper_t(low, solve_lower(low, rhs.copy()))
    norm = 0.0
    for r in range(N_UNKNOWNS):
        norm += rhs[r] * z[r]
    if not norm > 0.0:
        return DEGENERATE, h, np.nan, np.nan
    for r in range(N_UNKNOWNS):
        quad[r] = z[r] * used / norm
    # One pass for the offset and both residuals: with w = 1 / |g|^2, the offset is
    # c = -sum(w f) / sum(w), and sum w (f + c)^2 = sum(w f^2) + c sum(w f).
    sw = 0.0
    swf = 0.0
    swff = 0.0
    sin2 = 0.0
    for i in range(used):
        g0, g1, g2 = _gradient(quad, xs[i, 0], xs[i, 1], xs[i, 2])
        gg = g0 * g0 + g1 * g1 + g2 * g2
        if not gg > 0.0:
            return DEGENERATE, h, np.nan, np.nan
        f = _value(quad, xs[i, 0], xs[i, 1], xs[i, 2])
        sw += 1.0 / gg
        swf += f / gg
        swff += f * f / gg
        dot = ns[i, 0] * g0 + ns[i, 1] * g1 + ns[i, 2] * g2
        sin2 += max(1.0 - dot * dot / gg, 0.0)
    quad[9] = -swf / sw
    dist2 = max(swff + quad[9] * swf, 0.0)
    return OK, h, sin2 / used, h * np.sqrt(dist2 / used)


@njit(cache=True)
def _value(quad, x0, x1, x2):
    """x'ax + b'x (without the offset c) of packed coefficients."""
    return (quad[0] * x0 * x0 + quad[1] * x1 * x1 + quad[2] * x2 * x2
            + 2.0 * (quad[3] * x0 * x1 + quad[4] * x0 * x2 + quad[5] * x1 * x2)
            + quad[6] * x0 + quad[7] * x1 + quad[8] * x2)


@njit(cache=True)
def curvature_from_quadric(quad, h, d, max_dist):
    """Curvature of a fitted quadric at the foot point of the scaled position ``d``.

    Parameters
    ----------
    quad : ndarray, shape (N_QUAD,)
        As written by :func:`regress_normal_quadric`.
    h : float
        Its coordinates' unit.
    d : ndarray, shape (3,)
        The query point in the fit's scaled coordinates.
    max_dist : float
        A foot point farther than this (scaled units) from ``d`` is rejected.

    Returns
    -------
    status : int
        OK or NO_FOOT.
    k1, k2 : float
        Principal curvatures (input units), k1 >= k2, signed against ``n``.
    n, d1, d2 : ndarray, shape (3,)
        Unit normal (along the gradient, i.e. the fit centre's normal side) and principal
        directions.
    """
    a, b = quad_matrix(quad)
    # F(d + y) = y'ay + (2ad + b)'y + F(d): the foot point search starts at the origin.
    b_here = 2.0 * (a @ d) + b
    c_here = _value(quad, d[0], d[1], d[2]) + quad[9]
    y, ok = foot_point(a, b_here, c_here, max_dist)
    if not ok:
        z = np.zeros(3)
        return NO_FOOT, np.nan, np.nan, z, z, z
    g = 2.0 * (a @ y) + b_here
    k1, k2, n, d1, d2 = shape_operator(g, 2.0 * a)
    return OK, k1 / h, k2 / h, n, d1, d2


__all__ = ["MIN_POINTS_NQ", "N_QUAD", "curvature_from_quadric", "quad_matrix",
           "regress_normal_quadric"]
