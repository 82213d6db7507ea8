"""Curvature of an implicit quadric F(x) = x'Ax + b'x + c at the foot point of the origin.

Shared by both fit models: the Monge height function h(u, v) - w is a quadric too, so one routine
finds the foot point and evaluates the shape operator for all of them.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# Status codes (curvature.status.Status), repeated as plain ints for numba.
OK = 0
TOO_FEW = 1
DEGENERATE = 2
NO_FOOT = 3
NON_FINITE = 4


@njit(cache=True)
def mat_vec3(a, x0, x1, x2):
    """``a @ x`` of a (3, 3) matrix, written out: numba's ``@`` calls BLAS, whose call
    overhead is most of the time of a 3x3 product (curvature reads run one per point)."""
    out = np.empty(3)
    for r in range(3):
        out[r] = a[r, 0] * x0 + a[r, 1] * x1 + a[r, 2] * x2
    return out


@njit(cache=True, inline="always")
def sym_gradient(a00, a11, a22, a01, a02, a12, b0, b1, b2, x0, x1, x2):
    """grad F(x) = 2 a x + b with the symmetric ``a`` and ``b`` given by their entries, as
    three scalars (inlined, so loops calling it stay in SIMD lanes)."""
    return (2.0 * (a00 * x0 + a01 * x1 + a02 * x2) + b0,
            2.0 * (a01 * x0 + a11 * x1 + a12 * x2) + b1,
            2.0 * (a02 * x0 + a12 * x1 + a22 * x2) + b2)


@njit(cache=True)
def gradient_at(a, b, x):
    """grad F(x) = 2 a x + b of F = x'ax + b'x + c, without BLAS (:func:`mat_vec3`)."""
    g = mat_vec3(a, x[0], x[1], x[2])
    for r in range(3):
        g[r] = 2.0 * g[r] + b[r]
    return g


@njit(cache=True)
def foot_point(a, b, c, max_dist):
    """Point of F = 0 reached from the origin by gradient projection steps.

    Iterates x <- x - F g / |g|^2 (DESIGN.md 4.5), which lands on the surface along the
    gradient field; for a point near the surface it agrees with the closest point to second order
    in the distance.

    Parameters
    ----------
    a : ndarray, shape (3, 3)
    b : ndarray, shape (3,)
    c : float
    max_dist : float
        A foot point farther than this from the origin is rejected.

    Returns
    -------
    x : ndarray, shape (3,)
        Foot point.
    ok : bool
        False when the iteration stalls on a vanishing gradient, does not converge, or leaves
        the ball of radius ``max_dist``.
    """
    x0, x1, x2, ok = foot_point_xyz(a[0, 0], a[1, 1], a[2, 2], a[0, 1], a[0, 2], a[1, 2],
                                    b[0], b[1], b[2], c, max_dist)
    x = np.empty(3)
    x[0], x[1], x[2] = x0, x1, x2
    return x, ok


@njit(cache=True)
def foot_point_xyz(a00, a11, a22, a01, a02, a12, b0, b1, b2, c, max_dist):
    """:func:`foot_point` on the quadric's coefficients as scalars (no allocation; reads run
    it once per point).

    Returns
    -------
    x0, x1, x2 : float
        Foot point.
    ok : bool
    """
    x0 = x1 = x2 = 0.0
    ok = False
    for it in range(31):
        ax0 = a00 * x0 + a01 * x1 + a02 * x2
        ax1 = a01 * x0 + a11 * x1 + a12 * x2
        ax2 = a02 * x0 + a12 * x1 + a22 * x2
        # a x is needed for F as well, so the gradient is not sym_gradient's
        f = (x0 * ax0 + x1 * ax1 + x2 * ax2) + (b0 * x0 + b1 * x1 + b2 * x2) + c
        g0, g1, g2 = 2.0 * ax0 + b0, 2.0 * ax1 + b1, 2.0 * ax2 + b2
        gg = g0 * g0 + g1 * g1 + g2 * g2
        if it == 30:  # out of steps: accept a point already on the surface
            ok = abs(f) < 1e-9 * np.sqrt(gg)
            break
        if not gg > 1e-24:
            break
        step = f / gg
        x0, x1, x2 = x0 - step * g0, x1 - step * g1, x2 - step * g2
        if x0 * x0 + x1 * x1 + x2 * x2 > max_dist * max_dist:
            break
        if abs(step) * np.sqrt(gg) < 1e-13:
            ok = True
            break
    return x0, x1, x2, ok


@njit(cache=True)
def tangent_basis(n):
    """Two unit vectors completing the unit normal ``n`` (3,) to a right-handed frame."""
    a0, a1, a2, b0, b1, b2 = tangent_basis_xyz(n[0], n[1], n[2])
    t1 = np.empty(3)
    t1[0], t1[1], t1[2] = a0, a1, a2
    t2 = np.empty(3)
    t2[0], t2[1], t2[2] = b0, b1, b2
    return t1, t2


@njit(cache=True)
def tangent_basis_xyz(n0, n1, n2):
    """:func:`tangent_basis` of a normal given as scalars: t1 then t2, six scalars."""
    ax0, ax1, ax2 = abs(n0), abs(n1), abs(n2)
    # t1 = n x e, e the axis least aligned with n, then normalised; t2 = n x t1.
    if ax0 <= ax1 and ax0 <= ax2:
        c0, c1, c2 = 0.0, n2, -n1
    elif ax1 <= ax2:
        c0, c1, c2 = -n2, 0.0, n0
    else:
        c0, c1, c2 = n1, -n0, 0.0
    norm = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    c0, c1, c2 = c0 / norm, c1 / norm, c2 / norm
    return (c0, c1, c2, n1 * c2 - n2 * c1, n2 * c0 - n0 * c2, n0 * c1 - n1 * c0)


@njit(cache=True)
def eigen2(s11, s12, s22):
    """Eigenvalues k1 >= k2 of the symmetric 2x2 matrix [[s11, s12], [s12, s22]] and the unit
    eigenvector (e1, e2) of k1 ((1, 0) at an umbilic)."""
    half_tr = 0.5 * (s11 + s22)
    rad = np.sqrt(0.25 * (s11 - s22) ** 2 + s12 * s12)
    k1 = half_tr + rad
    k2 = half_tr - rad
    # Pick the better-conditioned of two formulas.
    if s11 >= s22:
        e1 = k1 - s22
        e2 = s12
    else:
        e1 = s12
        e2 = k1 - s11
    en = np.sqrt(e1 * e1 + e2 * e2)
    if en > 0.0:
        return k1, k2, e1 / en, e2 / en
    return k1, k2, 1.0, 0.0


@njit(cache=True)
def clear_outputs(j, k1, k2, residual, normals, dir1, dir2):
    """Set every curvature output of query ``j`` to NaN (a failed point keeps them so)."""
    k1[j] = np.nan
    k2[j] = np.nan
    residual[j] = np.nan
    for d in range(3):
        normals[j, d] = np.nan
        dir1[j, d] = np.nan
        dir2[j, d] = np.nan


@njit(cache=True)
def store_outputs(j, c1, c2, n, d1, d2, k1, k2, normals, dir1, dir2):
    """Write query ``j``'s curvatures, normal and directions if all are finite.

    Returns
    -------
    bool
        False (nothing written) when a value is NaN or infinite.
    """
    if not (np.isfinite(c1) and np.isfinite(c2) and np.all(np.isfinite(n))
            and np.all(np.isfinite(d1))):
        return False
    k1[j] = c1
    k2[j] = c2
    for d in range(3):
        normals[j, d] = n[d]
        dir1[j, d] = d1[d]
        dir2[j, d] = d2[d]
    return True


@njit(cache=True)
def store_xyz(j, c1, c2, n0, n1, n2, e0, e1, e2, k1, k2, normals, dir1, dir2):
    """:func:`store_outputs` of a normal ``n`` and direction ``d1 = e`` given as scalars
    (``d2 = n x d1``).

    Returns
    -------
    bool
        False (nothing written) when a value is NaN or infinite.
    """
    if not (np.isfinite(c1) and np.isfinite(c2) and np.isfinite(n0) and np.isfinite(n1)
            and np.isfinite(n2) and np.isfinite(e0) and np.isfinite(e1) and np.isfinite(e2)):
        return False
    k1[j] = c1
    k2[j] = c2
    normals[j, 0], normals[j, 1], normals[j, 2] = n0, n1, n2
    dir1[j, 0], dir1[j, 1], dir1[j, 2] = e0, e1, e2
    dir2[j, 0] = n1 * e2 - n2 * e1
    dir2[j, 1] = n2 * e0 - n0 * e2
    dir2[j, 2] = n0 * e1 - n1 * e0
    return True


@njit(cache=True)
def shape_operator(g, hess):
    """Principal curvatures and directions of an implicit surface at a point.

    The shape operator of F = 0 is P H P / |g| on the tangent plane (P = I - n n', n = g/|g|).
    Its eigenvalues are the principal curvatures, positive where the surface bends away from n
    (a sphere |x|^2 - r^2 gives +1/r with the outward n).

    Parameters
    ----------
    g : ndarray, shape (3,)
        Gradient of F at the point (nonzero).
    hess : ndarray, shape (3, 3)
        Hessian of F.

    Returns
    -------
    k1, k2 : float
        Principal curvatures, k1 >= k2.
    n, d1, d2 : ndarray, shape (3,)
        Unit normal g/|g| and unit principal directions of k1 and k2 (d2 = n x d1).
    """
    k1, k2, n0, n1, n2, e0, e1, e2 = shape_operator_xyz(
        g[0], g[1], g[2], hess[0, 0], hess[1, 1], hess[2, 2], hess[0, 1], hess[0, 2],
        hess[1, 2])
    n = np.empty(3)
    n[0], n[1], n[2] = n0, n1, n2
    d1 = np.empty(3)
    d1[0], d1[1], d1[2] = e0, e1, e2
    return k1, k2, n, d1, np.cross(n, d1)


@njit(cache=True)
def shape_operator_xyz(g0, g1, g2, h00, h11, h22, h01, h02, h12):
    """:func:`shape_operator` on scalars (gradient, then the Hessian's six entries): k1, k2,
    the unit normal's and d1's components (d2 = n x d1); no allocation."""
    gn = np.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
    n0, n1, n2 = g0 / gn, g1 / gn, g2 / gn
    a0, a1, a2, b0, b1, b2 = tangent_basis_xyz(n0, n1, n2)
    ha0 = h00 * a0 + h01 * a1 + h02 * a2
    ha1 = h01 * a0 + h11 * a1 + h12 * a2
    ha2 = h02 * a0 + h12 * a1 + h22 * a2
    hb0 = h00 * b0 + h01 * b1 + h02 * b2
    hb1 = h01 * b0 + h11 * b1 + h12 * b2
    hb2 = h02 * b0 + h12 * b1 + h22 * b2
    s11 = (a0 * ha0 + a1 * ha1 + a2 * ha2) / gn
    s12 = 0.5 * ((a0 * hb0 + a1 * hb1 + a2 * hb2) + (b0 * ha0 + b1 * ha1 + b2 * ha2)) / gn
    s22 = (b0 * hb0 + b1 * hb1 + b2 * hb2) / gn
    k1, k2, e1, e2 = eigen2(s11, s12, s22)
    return (k1, k2, n0, n1, n2, e1 * a0 + e2 * b0, e1 * a1 + e2 * b1, e1 * a2 + e2 * b2)


@njit(cache=True)
def sampson_rms(a, b, c, xs):
    """RMS first-order distance |F(x)| / |grad F(x)| of points ``xs`` (m, 3) to F = 0."""
    total = 0.0
    m = xs.shape[0]
    for i in range(m):
        x0, x1, x2 = xs[i, 0], xs[i, 1], xs[i, 2]
        # A x, written out: this runs once per neighbor and must not allocate.
        ax0 = a[0, 0] * x0 + a[0, 1] * x1 + a[0, 2] * x2
        ax1 = a[1, 0] * x0 + a[1, 1] * x1 + a[1, 2] * x2
        ax2 = a[2, 0] * x0 + a[2, 1] * x1 + a[2, 2] * x2
        f = x0 * ax0 + x1 * ax1 + x2 * ax2 + b[0] * x0 + b[1] * x1 + b[2] * x2 + c
        g0 = 2.0 * ax0 + b[0]
        g1 = 2.0 * ax1 + b[1]
        g2 = 2.0 * ax2 + b[2]
        gg = g0 * g0 + g1 * g1 + g2 * g2
        total += f * f / gg if gg > 1e-300 else f * f
    return np.sqrt(total / m)
