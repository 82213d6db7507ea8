"""Off-centre fits for clean clouds: a point beside a curvature jump reads a neighbor's fit.

A fit centred on a face point one spacing from a fillet straddles both and is exact on neither;
a neighbor a few spacings further in fits the face alone, exactly. Here a point whose own fit is
not exact, or is singular at it, takes the fit of one of its nearest neighbors whose own fit is
exact, provided the point lies on that neighbor's quadric (within ``tol``), and reads it at its
own foot point. This is the one-sided window of feature-preserving fits (e.g. Fleishman,
Cohen-Or & Silva, "Robust moving least-squares fitting with sharp features", SIGGRAPH 2005, who
grow it from a clean seed): on a piecewise quadric part every point then reads its own piece
exactly. On a surface that is no quadric no fit is exact and nothing changes (residuals are not
compared otherwise: a small fit with nearly as many points as unknowns has a tiny residual
there and reads poorly).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..neighborhoods.kdtree import KNN_BLOCK, knn_point, knn_scratch
from .kernels import MAX_FOOT_DIST, SOLVER_TAUBIN, fit_implicit, gather_local
from .quadric import (
    DEGENERATE,
    OK,
    clear_outputs,
    foot_point,
    gradient_at,
    mat_vec3,
    shape_operator,
    store_outputs,
)

__all__ = ["adopt_neighbor_fits"]

# Most candidates tried per adopting point, best residual first (plane pairs that fit a
# face with two fillet points are exact and singular: several may come first).
TRIES = 24
# Smallest gradient at the read point, relative to its RMS over the fitted points, of a
# regular quadric (about 1 on any quadric a small patch is fitted by).
REGULAR = 0.5


@njit(cache=True)
def _read_fit(points, p, q, nbr, tol):
    """Implicit quadric over ``q`` and ``nbr``, read at ``p``.

    Returns
    -------
    ok : bool
        The fit succeeded, p lies within ``tol`` (input units) of it and the quadric is
        regular there: the gradient at p's foot point is at least :data:`REGULAR` times its
        RMS over the fitted points. (Near a face, points on a plane plus two or three fillet
        points are fitted exactly by a plane pair, whose gradient vanishes along the line where
        its planes meet; a foot point near that line reads any curvature.)
    c1, c2 : float
    n, d1, d2 : ndarray, shape (3,)
    """
    xs, scale = gather_local(points, q, nbr, True)
    zero = np.zeros(3)
    if not scale > 0.0:
        return False, 0.0, 0.0, zero, zero, zero
    a, b, c, ok = fit_implicit(xs, SOLVER_TAUBIN)
    if not ok:
        return False, 0.0, 0.0, zero, zero, zero
    xp = (points[p] - points[q]) / scale
    # F moved to p: F(x + xp) = x'ax + (2 a xp + b)'x + F(xp).
    bp = gradient_at(a, b, xp)
    cp = np.sum(xp * mat_vec3(a, xp[0], xp[1], xp[2])) + np.sum(b * xp) + c
    x0, found = foot_point(a, bp, cp, MAX_FOOT_DIST)
    if not found or np.sqrt(np.sum(x0 * x0)) * scale > tol:
        return False, 0.0, 0.0, zero, zero, zero
    g = gradient_at(a, bp, x0)
    gg = 0.0
    for i in range(xs.shape[0]):
        gi = gradient_at(a, b, xs[i])
        gg += np.sum(gi * gi)
    if np.sum(g * g) < REGULAR * REGULAR * gg / xs.shape[0]:
        return False, 0.0, 0.0, zero, zero, zero
    c1, c2, n, d1, d2 = shape_operator(g, 2.0 * a)
    return True, c1 / scale, c2 / scale, n, d1, d2


@njit(parallel=True, cache=True)
def adopt_neighbor_fits(points, tree, m, fit_residual, fit_count, fit_reach, exact, tol,
                        k1, k2, normals, dir1, dir2, residual, status, count, reach):
    """Give each point the fit of a neighbor whose own fit is far better (module docstring).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    tree : tuple
        :func:`~curvature.neighborhoods.kdtree.build_tree` over ``points``.
    m : int
        Nearest neighbors considered.
    fit_residual : ndarray, shape (n,)
        Residual of every point's own fit (inf or NaN where it failed); read only.
    fit_count : ndarray, shape (n,), int64
        Neighbors of every point's own fit; read only.
    fit_reach : ndarray, shape (n,)
        Radius of every point's own fit's neighborhood; read only.
    exact : float
        Residual (input units) up to which a fit is exact: a point whose own fit is not exact
        (or is singular at it) takes the fit of an exact neighbor.
    tol : float
        Largest distance of the point to the candidate's quadric.
    k1, k2, normals, dir1, dir2, residual, status, count
        Outputs as in ``fit_batch`` plus the fit's neighbor count: rewritten where a
        neighbor's fit is adopted (its residual is reported), cleared with status DEGENERATE
        where the point's own fit is singular at it and no neighbor's fit serves, untouched
        elsewhere.
    reach : ndarray, shape (n,)
        Output: how far each point's result now depends (its candidates and their fits).
    """
    n = points.shape[0]
    kmax = max(m, np.int64(fit_count.max()))
    for blk in prange((n + KNN_BLOCK - 1) // KNN_BLOCK):
        scratch = knn_scratch(tree, kmax)
        ids = np.empty(kmax, np.int64)
        ds = np.empty(kmax)
        qids = np.empty(kmax, np.int64)
        qds = np.empty(kmax)
        cand = np.empty(m, np.int64)
        cres = np.empty(m)
        for p in range(blk * KNN_BLOCK, min(n, (blk + 1) * KNN_BLOCK)):
            reach[p] = fit_reach[p]
            knn_point(points, tree, p, m, ds, ids, scratch[0], scratch[1], scratch[2],
                      scratch[3])
            own = fit_residual[p] if np.isfinite(fit_residual[p]) else np.inf
            singular = False
            if own <= exact and fit_count[p] <= m:
                # An exact fit may still be a singular plane pair (:func:`_read_fit`); its
                # neighbors are the first fit_count of these.
                ok, c1, c2, nn, d1, d2 = _read_fit(points, p, p, ids[:fit_count[p]], np.inf)
                if not ok:
                    singular = True
                    own = np.inf
            found = 0
            for i in range(m):
                q = ids[i]
                reach[p] = max(reach[p], np.sqrt(ds[i]) + fit_reach[q])
                r = fit_residual[q]
                if r <= exact < own:
                    cand[found] = q
                    cres[found] = r
                    found += 1
            adopted = False
            order = np.argsort(cres[:found], kind="mergesort")
            for t in range(min(TRIES, found)):
                q = cand[order[t]]
                snode, sdist, bufd, bufi = scratch
                knn_point(points, tree, q, fit_count[q], qds, qids, snode, sdist, bufd, bufi)
                ok, c1, c2, nn, d1, d2 = _read_fit(points, p, q, qids[:fit_count[q]], tol)
                if ok and store_outputs(p, c1, c2, nn, d1, d2, k1, k2, normals, dir1, dir2):
                    residual[p] = fit_residual[q]
                    status[p] = OK
                    count[p] = fit_count[q]
                    adopted = True
                    break
            if singular and not adopted:
                clear_outputs(p, k1, k2, residual, normals, dir1, dir2)
                status[p] = DEGENERATE
