"""Standard errors of k1, k2 and H of a fixed-neighborhood fit (least-squares covariance).

Every fit model reads its curvature off a local surface whose second-order shape, to first
order, is the quadratic height function ``z = a u^2 + b uv + c v^2 + d u + e v + f`` over the
tangent plane of the estimated normal, with ``u`` along ``dir1`` and ``v`` along ``dir2``. In
that frame the Hessian is diagonal at the foot point, so ``k1 = 2a``, ``k2 = 2c`` and
``H = a + c``, and the derivatives of the eigenvalues with respect to ``b`` vanish: the
covariance of the curvatures is that of ``(a, c)``, ``sigma^2 (X^T X)^-1`` of the design
``X`` (rows ``u^2, uv, v^2, u, v, 1`` of the fitted points) with ``sigma^2`` the residual
variance (``residual^2 * m / (m - 6)``). The full quadratic basis makes the result independent
of where the origin lies in the tangent plane. Each fit model gets a factor ``calib`` (its
error is larger than the height function's when it has more unknowns; measured in
benchmarks/uncertainty.py).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .linalg import cholesky, solve_lower
from .quadric import OK

__all__ = ["MONGE_TERMS", "add_neighbor_spread", "design_std"]

#: Coefficients of the quadratic height function.
MONGE_TERMS = 6
# Rank tolerance of the normal matrix (relative to its largest diagonal entry).
RANK_TOL = 1e-12


@njit(cache=True)
def _normal_matrix(points, p, nbr, include_self, t1, t2):
    """``X^T X`` of the height-function design in units of the RMS neighbor distance.

    Returns
    -------
    xtx : ndarray, shape (6, 6)
    h : float
        RMS distance of the neighbors from p.
    m : int
        Fitted points (p included when ``include_self``).
    """
    k = nbr.shape[0]
    ss = 0.0
    for i in range(k):
        for d in range(3):
            v = points[nbr[i], d] - points[p, d]
            ss += v * v
    h = np.sqrt(ss / k) if k > 0 else 0.0
    xtx = np.zeros((MONGE_TERMS, MONGE_TERMS))
    row = np.empty(MONGE_TERMS)
    start = -1 if include_self else 0
    for i in range(start, k):
        u = 0.0
        v = 0.0
        if i >= 0 and h > 0.0:
            for d in range(3):
                x = (points[nbr[i], d] - points[p, d]) / h
                u += x * t1[d]
                v += x * t2[d]
        row[0], row[1], row[2], row[3], row[4], row[5] = u * u, u * v, v * v, u, v, 1.0
        for r in range(MONGE_TERMS):
            for c in range(MONGE_TERMS):
                xtx[r, c] += row[r] * row[c]
    return xtx, h, k - start


@njit(cache=True)
def _norm_solved(low, g):
    """``sqrt(g^T (L L^T)^-1 g)``: the standard error of ``g . coef`` per unit of sigma."""
    y = solve_lower(low, g)
    return np.sqrt(np.sum(y * y))


@njit(parallel=True, cache=True)
def design_std(points, query, indptr, indices, include_self, dir1, dir2, residual, status,
               calib, k1_std, k2_std, mean_std):
    """Standard errors of every query point's k1, k2 and H (module docstring).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    query : ndarray, shape (m,), int64
    indptr : ndarray, shape (m + 1,), int64
    indices : ndarray, shape (nnz,), int32 or int64
        The neighborhoods the fits used (CSR, query point not listed).
    include_self : bool
        Whether p itself took part in the fit.
    dir1, dir2 : ndarray, shape (m, 3)
        Principal directions of the fits.
    residual : ndarray, shape (m,)
        RMS distance of the fitted points to the fitted surface.
    status : ndarray, shape (m,), int8
    calib : float
        Factor of the fit model.
    k1_std, k2_std, mean_std : ndarray, shape (m,)
        Outputs in 1 / length: NaN where the status is not OK, inf where the design does
        not determine the curvature (as many points as unknowns, or rank deficient).
    """
    e_k1 = np.zeros(MONGE_TERMS)
    e_k1[0] = 2.0
    e_k2 = np.zeros(MONGE_TERMS)
    e_k2[2] = 2.0
    e_h = np.zeros(MONGE_TERMS)
    e_h[0] = 1.0
    e_h[2] = 1.0
    for j in prange(query.shape[0]):
        k1_std[j] = np.nan
        k2_std[j] = np.nan
        mean_std[j] = np.nan
        if status[j] != OK:
            continue
        nbr = indices[indptr[j]:indptr[j + 1]]
        xtx, h, m = _normal_matrix(points, query[j], nbr, include_self, dir1[j], dir2[j])
        k1_std[j] = np.inf
        k2_std[j] = np.inf
        mean_std[j] = np.inf
        if m <= MONGE_TERMS or not h > 0.0:
            continue
        low, ok = cholesky(xtx, RANK_TOL)
        if not ok:
            continue
        # residual variance with the degrees of freedom of the fit, in units of h
        sigma = calib * residual[j] * np.sqrt(m / (m - MONGE_TERMS)) / h
        unit = sigma / h
        k1_std[j] = unit * _norm_solved(low, e_k1)
        k2_std[j] = unit * _norm_solved(low, e_k2)
        mean_std[j] = unit * _norm_solved(low, e_h)


@njit(parallel=True, cache=True)
def add_neighbor_spread(k1, k2, normals, graph, weight, k1_std, k2_std, mean_std, skip):
    """Widen each point's standard errors by how far its neighbors' curvatures lie from its
    own, in place: ``std = hypot(std, weight * spread)`` with ``spread`` the RMS difference
    over the neighbors with an estimate.

    A neighbor whose normal points the other way is read with its curvatures negated and
    swapped (the same surface seen from the other side), so the spread does not depend on how
    the normals were oriented. Points without an estimate (NaN k1) keep their NaN.

    Parameters
    ----------
    k1, k2 : ndarray, shape (n,)
    normals : ndarray, shape (n, 3)
    graph : ndarray, shape (n, g), int
        Each point's nearest neighbors, -1 padded (as
        :func:`curvature.orientation.first_neighbors`); the point itself, where listed, is
        skipped.
    weight : float
    k1_std, k2_std, mean_std : ndarray, shape (n,)
        Standard errors, updated in place (only the point's own: the spread reads no
        standard error).
    skip : ndarray, shape (n,), bool
        Points whose standard errors stay as they are (their curvatures are still read as
        the others' neighbors).
    """
    n = k1.shape[0]
    for i in prange(n):
        if skip[i] or not np.isfinite(k1[i]):
            continue
        h = 0.5 * (k1[i] + k2[i])
        s1, s2, sh = 0.0, 0.0, 0.0
        count = 0
        for c in range(graph.shape[1]):
            j = graph[i, c]
            if j < 0 or j == i or not (np.isfinite(k1[j]) and np.isfinite(k2[j])):
                continue
            a, b = k1[j], k2[j]
            if (normals[i, 0] * normals[j, 0] + normals[i, 1] * normals[j, 1]
                    + normals[i, 2] * normals[j, 2]) < 0.0:
                a, b = -k2[j], -k1[j]
            s1 += (a - k1[i]) ** 2
            s2 += (b - k2[i]) ** 2
            sh += (0.5 * (a + b) - h) ** 2
            count += 1
        if count == 0:
            continue
        k1_std[i] = np.hypot(k1_std[i], weight * np.sqrt(s1 / count))
        k2_std[i] = np.hypot(k2_std[i], weight * np.sqrt(s2 / count))
        mean_std[i] = np.hypot(mean_std[i], weight * np.sqrt(sh / count))
