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
def quadric_value_grad(a, b, c, x):
    """F(x) and grad F(x) for F = x'Ax + b'x + c; ``a`` (3, 3) symmetric, ``b`` (3,)."""
    ax = a @ x
    f = np.sum(x * ax) + np.sum(b * x) + c
    g = 2.0 * ax + b
    return f, g


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
    x = np.zeros(3)
    for _ in range(30):
        f, g = quadric_value_grad(a, b, c, x)
        gg = np.sum(g * g)
        if not gg > 1e-24:
            return x, False
        step = f / gg
        x = x - step * g
        if np.sum(x * x) > max_dist * max_dist:
            return x, False
        if abs(step) * np.sqrt(gg) < 1e-13:
            return x, True
    f, g = quadric_value_grad(a, b, c, x)
    return x, abs(f) < 1e-9 * np.sqrt(np.sum(g * g))


@njit(cache=True)
def tangent_basis(n):
    """Two unit vectors completing the unit normal ``n`` (3,) to a right-handed frame."""
    ax = np.abs(n)
    if ax[0] <= ax[1] and ax[0] <= ax[2]:
        helper = np.array([1.0, 0.0, 0.0])
    elif ax[1] <= ax[2]:
        helper = np.array([0.0, 1.0, 0.0])
    else:
        helper = np.array([0.0, 0.0, 1.0])
    t1 = np.cross(n, helper)
    t1 /= np.sqrt(np.sum(t1 * t1))
    t2 = np.cross(n, t1)
    return t1, t2


@njit(cache=True)
def tangent_eigen(s11, s12, s22, t1, t2):
    """Eigen-decomposition of a symmetric 2x2 shape operator given in a tangent basis.

    Parameters
    ----------
    s11, s12, s22 : float
        Entries of the operator in the basis (t1, t2).
    t1, t2 : ndarray, shape (3,)
        Orthonormal tangent vectors.

    Returns
    -------
    k1, k2 : float
        Eigenvalues, k1 >= k2.
    d1 : ndarray, shape (3,)
        Unit eigenvector of k1 in 3D (t1 at an umbilic, where every direction is principal).
    """
    half_tr = 0.5 * (s11 + s22)
    rad = np.sqrt(0.25 * (s11 - s22) ** 2 + s12 * s12)
    k1 = half_tr + rad
    k2 = half_tr - rad
    # Eigenvector of k1 in the (t1, t2) basis; pick the better-conditioned of two formulas.
    if s11 >= s22:
        e1 = k1 - s22
        e2 = s12
    else:
        e1 = s12
        e2 = k1 - s11
    en = np.sqrt(e1 * e1 + e2 * e2)
    if en > 0.0:
        return k1, k2, (e1 * t1 + e2 * t2) / en
    return k1, k2, t1.copy()


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
    gn = np.sqrt(np.sum(g * g))
    n = g / gn
    t1, t2 = tangent_basis(n)
    h1 = hess @ t1
    h2 = hess @ t2
    s11 = np.sum(t1 * h1) / gn
    s12 = 0.5 * (np.sum(t1 * h2) + np.sum(t2 * h1)) / gn
    s22 = np.sum(t2 * h2) / gn
    k1, k2, d1 = tangent_eigen(s11, s12, s22, t1, t2)
    d2 = np.cross(n, d1)
    return k1, k2, n, d1, d2


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
