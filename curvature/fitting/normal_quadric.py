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

from .linalg import cholesky, dot, solve_lower, solve_upper_t, total
from .quadric import (
    DEGENERATE,
    NO_FOOT,
    OK,
    TOO_FEW,
    foot_point_xyz,
    shape_operator_xyz,
    sym_gradient,
)

# a00, a11, a22, a01, a02, a12, b0, b1, b2 and the offset c.
N_QUAD = 10
N_UNKNOWNS = 9
MIN_POINTS_NQ = 12
# Relative ridge on the normal matrix: a plane (all normals equal) leaves a two-dimensional
# null space (b along n, a = n n'); the ridge picks its smallest member, which has no curvature.
RIDGE = 1e-12


# g(x) = 2ax + b is linear in the 9 unknowns theta; each of its 3 components involves 4 of
# them: g_d = sum_j vals[d, j] * theta[ROW_COLS[d, j]].
ROW_COLS = np.array([[0, 3, 4, 6], [1, 3, 5, 7], [2, 4, 5, 8]], np.int64)
# The same entries as multiples of y = (x0, x1, x2, 1):
# vals[d, j] = ROW_SCALE[j] * y[ROW_VARS[d, j]].
ROW_VARS = np.array([[0, 1, 2, 3], [1, 0, 2, 3], [2, 0, 1, 3]], np.int64)
ROW_SCALE = np.array([2.0, 2.0, 2.0, 1.0])


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
    # Offsets from p and normals flipped to agree with p's, of the points with a known normal,
    # one row per coordinate so the sums below run over contiguous memory.
    xs = np.empty((3, m))
    ns = np.empty((3, m))
    used = 0
    ss = 0.0
    for i in range(m):
        q = p if (include_self and i == 0) else nbr[i - (1 if include_self else 0)]
        nx, ny, nz = field[q, 0], field[q, 1], field[q, 2]
        if not (np.isfinite(nx) and np.isfinite(ny) and np.isfinite(nz)):
            continue
        s = 1.0 if nx * n_p[0] + ny * n_p[1] + nz * n_p[2] >= 0.0 else -1.0
        for d in range(3):
            xs[d, used] = points[q, d] - points[p, d]
            ss += xs[d, used] * xs[d, used]
        ns[0, used] = s * nx
        ns[1, used] = s * ny
        ns[2, used] = s * nz
        used += 1
    if used < MIN_POINTS_NQ:
        return TOO_FEW, 0.0, np.nan, np.nan
    h = np.sqrt(ss / used)
    if not h > 0.0:
        return DEGENERATE, 0.0, np.nan, np.nan
    for d in range(3):
        for i in range(used):
            xs[d, i] /= h
    # |(I - nn') X theta|^2 = theta' (X'X - V'V) theta, rows of V being v_i = X_i'n_i. X'X
    # needs only the moments of x up to second order; V'V and the right-hand side sum(v_i)
    # are dot products and sums of V's columns (rows of `vs`).
    vs = np.empty((N_UNKNOWNS, used))
    for i in range(used):
        x0, x1, x2 = xs[0, i], xs[1, i], xs[2, i]
        n0, n1, n2 = ns[0, i], ns[1, i], ns[2, i]
        vs[0, i] = 2.0 * n0 * x0
        vs[1, i] = 2.0 * n1 * x1
        vs[2, i] = 2.0 * n2 * x2
        vs[3, i] = 2.0 * (n0 * x1 + n1 * x0)
        vs[4, i] = 2.0 * (n0 * x2 + n2 * x0)
        vs[5, i] = 2.0 * (n1 * x2 + n2 * x1)
        vs[6, i] = n0
        vs[7, i] = n1
        vs[8, i] = n2
    # moments[a, b] = sum of y_a y_b over the points, y = (x0, x1, x2, 1).
    moments = np.empty((4, 4))
    for a in range(3):
        moments[a, 3] = moments[3, a] = total(xs[a], used)
        for b in range(a, 3):
            moments[a, b] = moments[b, a] = dot(xs[a], xs[b], used)
    moments[3, 3] = used
    mat = np.zeros((N_UNKNOWNS, N_UNKNOWNS))
    for d in range(3):
        for a in range(4):
            for b in range(4):
                mat[ROW_COLS[d, a], ROW_COLS[d, b]] += (
                    ROW_SCALE[a] * ROW_SCALE[b] * moments[ROW_VARS[d, a], ROW_VARS[d, b]])
    rhs = np.empty(N_UNKNOWNS)
    trace = 0.0
    for r in range(N_UNKNOWNS):
        rhs[r] = total(vs[r], used)
        for c in range(r, N_UNKNOWNS):
            mat[r, c] -= dot(vs[r], vs[c], used)
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
    # The offset and both residuals: with w = 1 / |g|^2, the offset is c = -sum(w f) / sum(w),
    # and sum w (f + c)^2 = sum(w f^2) + c sum(w f). Coefficients as scalars and no exit in
    # the loop, so it runs in SIMD lanes.
    a00, a11, a22, a01, a02, a12 = quad[0], quad[1], quad[2], quad[3], quad[4], quad[5]
    b0, b1, b2 = quad[6], quad[7], quad[8]
    w = np.empty(used)
    wf = np.empty(used)
    f = np.empty(used)
    sin2 = np.empty(used)
    flat = 0
    for i in range(used):
        x0, x1, x2 = xs[0, i], xs[1, i], xs[2, i]
        g0, g1, g2 = sym_gradient(a00, a11, a22, a01, a02, a12, b0, b1, b2, x0, x1, x2)
        gg = g0 * g0 + g1 * g1 + g2 * g2
        flat += 0 if gg > 0.0 else 1
        w[i] = 1.0 / gg
        f[i] = (a00 * x0 * x0 + a11 * x1 * x1 + a22 * x2 * x2
                + 2.0 * (a01 * x0 * x1 + a02 * x0 * x2 + a12 * x1 * x2)
                + b0 * x0 + b1 * x1 + b2 * x2)
        wf[i] = w[i] * f[i]
        along = ns[0, i] * g0 + ns[1, i] * g1 + ns[2, i] * g2
        sin2[i] = max(1.0 - along * along * w[i], 0.0)
    if flat > 0:
        return DEGENERATE, h, np.nan, np.nan
    sw = total(w, used)
    swf = total(wf, used)
    swff = dot(wf, f, used)
    quad[9] = -swf / sw
    dist2 = max(swff + quad[9] * swf, 0.0)
    return OK, h, total(sin2, used) / used, h * np.sqrt(dist2 / used)


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
    st, k1, k2, n0, n1, n2, e0, e1, e2 = quadric_curvature_xyz(quad, h, d[0], d[1], d[2],
                                                               max_dist)
    if st != OK:
        z = np.zeros(3)
        return NO_FOOT, np.nan, np.nan, z, z, z
    n = np.empty(3)
    n[0], n[1], n[2] = n0, n1, n2
    d1 = np.empty(3)
    d1[0], d1[1], d1[2] = e0, e1, e2
    return OK, k1, k2, n, d1, np.cross(n, d1)


@njit(cache=True)
def quadric_curvature_xyz(quad, h, d0, d1, d2, max_dist):
    """:func:`curvature_from_quadric` at the scaled position ``(d0, d1, d2)``, on scalars
    (reads run it once per point; no allocation).

    Returns
    -------
    status : int
        OK or NO_FOOT.
    k1, k2 : float
        Principal curvatures (input units; NaN without a foot point).
    n0, n1, n2, e0, e1, e2 : float
        Unit normal and unit direction of k1 (d2 = n x d1).
    """
    a00, a11, a22, a01, a02, a12 = quad[0], quad[1], quad[2], quad[3], quad[4], quad[5]
    # F(d + y) = y'ay + (2ad + b)'y + F(d): the foot point search starts at the origin.
    b0, b1, b2 = sym_gradient(a00, a11, a22, a01, a02, a12, quad[6], quad[7], quad[8],
                              d0, d1, d2)
    c = _value(quad, d0, d1, d2) + quad[9]
    y0, y1, y2, ok = foot_point_xyz(a00, a11, a22, a01, a02, a12, b0, b1, b2, c, max_dist)
    if not ok:
        return NO_FOOT, np.nan, np.nan, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    g0, g1, g2 = sym_gradient(a00, a11, a22, a01, a02, a12, b0, b1, b2, y0, y1, y2)
    k1, k2, n0, n1, n2, e0, e1, e2 = shape_operator_xyz(
        g0, g1, g2, 2.0 * a00, 2.0 * a11, 2.0 * a22, 2.0 * a01, 2.0 * a02, 2.0 * a12)
    return OK, k1 / h, k2 / h, n0, n1, n2, e0, e1, e2


__all__ = ["MIN_POINTS_NQ", "N_QUAD", "curvature_from_quadric", "quadric_curvature_xyz",
           "regress_normal_quadric"]
