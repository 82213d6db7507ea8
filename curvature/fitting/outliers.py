"""Points that lie off the surface their neighbors describe (scanner outliers).

A scan's outliers (mixed pixels, reflections, dust) sit far from the surface compared with how
thick the surface's own sample is. For every point p with unit normal n (stage-1 PCA) and
neighbors q_i, the offset of p from the neighbors' centroid c along n is compared with the
neighbors' own spread along n (their RMS offset from c): p is an outlier when

    |(p - c) . n| > OUTLIER_SIGMAS * thickness + OUTLIER_FLOOR * spacing  (4 and 0.2).

The floor keeps noise-free clouds (thickness 0) from flagging rounding. Curvature sag raises the
thickness and the offset alike, so fillets are not flagged.

An outlier inside a thin wall, between its two faces, is not off that plane: the neighbors'
centroid lies in the wall's middle and their spread is half the wall's thickness. Nor is one
just past a thin wedge's rounded tip. Both lie on no sheet of their own (:func:`off_sheets`):
fewer than 3 of their 8 nearest neighbors have them within ``OWN_SHEET_NOISE * noise +
OWN_SHEET_FLOOR * spacing`` of their tangent planes, while a point on a face has most of its
nearest neighbors on its own face. A neighbor counts only up to OWN_SHEET_REACH times its own
8th neighbor's distance from the point: a face's plane, carried farther, runs on past the
wedge's tip. The test needs the cloud's noise, so clean clouds keep the other two, and it runs
where the stage-1 neighborhood is far from flat (OWN_SHEET_CANDIDATE), as a wall's is.

An outlier far from every surface (inside a part's volume, say) has no plane to be off: its
neighbors come from several faces and their spread is wide. It is *isolated* instead: the
distance to its 8th nearest neighbor exceeds ISOLATION (2.5) times the median of that distance
over its 8 nearest neighbors (:func:`isolated`). Comparing with the neighbors, not with the
whole cloud, keeps sparse but genuine regions of a scan (far from the scanner, say) unflagged.

Outliers' normals are left out of every normal fit and their positions out of the positional
fits, so they cannot drag a fit; they still get a result of their own.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["ISOLATION", "ISOLATION_K", "OUTLIER_FLOOR", "OUTLIER_SIGMAS", "OWN_SHEET_CANDIDATE",
           "OWN_SHEET_FLOOR", "OWN_SHEET_K", "OWN_SHEET_NOISE", "OWN_SHEET_RANK",
           "OWN_SHEET_REACH", "isolated", "off_sheets", "off_surface", "sheet_limit"]

#: Offsets beyond this many neighbor thicknesses are outliers.
OUTLIER_SIGMAS = 4.0
#: Plus this share of the point spacing (noise-free clouds have no thickness).
OUTLIER_FLOOR = 0.2
#: The test of :func:`off_sheets` (module docstring). A point lies on a sheet of its own where
#: at least OWN_SHEET_RANK of its OWN_SHEET_K nearest neighbors have it within
#: ``OWN_SHEET_NOISE * noise + OWN_SHEET_FLOOR * spacing`` of their tangent planes: 4 standard
#: deviations of the difference of two noisy heights, plus a share of the plan's spacing (its
#: 24th neighbor's distance) for the sag of curved surfaces (with 0.1 instead of 0.3, 18
#: points of the Stanford bunny's mesh, whose noise is 1.4 % of that spacing, were flagged;
#: with 0.3 none). It is tested where the stage-1 neighborhood's flatness exceeds
#: OWN_SHEET_CANDIDATE (a noisy plane reads 0.001, fillets 0.006 to 0.02, a slab 0.1); a
#: neighbor counts up to OWN_SHEET_REACH times its own ISOLATION_K-th neighbor's distance
#: from the point.
OWN_SHEET_K = 8
OWN_SHEET_RANK = 3
OWN_SHEET_NOISE = 4.0 * np.sqrt(2.0)
OWN_SHEET_FLOOR = 0.3
OWN_SHEET_CANDIDATE = 0.02
OWN_SHEET_REACH = 1.5
#: Neighbors of the isolation test, and how much farther than its neighbors' a point's
#: ISOLATION_K-th neighbor must be for the point to count as isolated.
ISOLATION_K = 8
ISOLATION = 2.5


@njit(parallel=True, cache=True)
def off_surface(points, query, nbr, normals, spacing, out):
    """Flag the query points that lie off their neighbors' surface (module docstring).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    query : ndarray, shape (m,), int64
    nbr : ndarray, shape (m, k)
        Neighbors of each query point (the point itself not listed).
    normals : ndarray, shape (m, 3)
        Unit normal of each query point (NaN: never flagged).
    spacing : float
        Point spacing of the cloud.
    out : ndarray, shape (m,), bool
        Output flags.
    """
    k = nbr.shape[1]
    for j in prange(query.shape[0]):
        n0, n1, n2 = normals[j, 0], normals[j, 1], normals[j, 2]
        out[j] = False
        if not (np.isfinite(n0) and np.isfinite(n1) and np.isfinite(n2)) or k < 3:
            continue
        # Heights of the neighbors and of p along n; offsets are taken from their mean.
        mean = 0.0
        for i in range(k):
            q = nbr[j, i]
            mean += points[q, 0] * n0 + points[q, 1] * n1 + points[q, 2] * n2
        mean /= k
        ss = 0.0
        for i in range(k):
            q = nbr[j, i]
            d = points[q, 0] * n0 + points[q, 1] * n1 + points[q, 2] * n2 - mean
            ss += d * d
        p = query[j]
        off = abs(points[p, 0] * n0 + points[p, 1] * n1 + points[p, 2] * n2 - mean)
        out[j] = off > OUTLIER_SIGMAS * np.sqrt(ss / k) + OUTLIER_FLOOR * spacing


def sheet_limit(noise: float, spacing: float) -> float:
    """The ``limit`` of :func:`off_sheets` for a cloud's ``noise`` (standard deviation across
    the surface) and plan ``spacing`` (length unit); inf where the noise is not finite or
    zero (no test)."""
    if not np.isfinite(noise) or noise <= 0.0:
        return np.inf
    return OWN_SHEET_NOISE * noise + OWN_SHEET_FLOOR * spacing


@njit(parallel=True, cache=True)
def off_sheets(points, query, nbr, normals, reach, excluded, limit, out):
    """Flag the query points that lie on no sheet of their nearest neighbors (module
    docstring).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    query : ndarray, shape (m,), int64
    nbr : ndarray, shape (m, k)
        Nearest neighbors of each query point, nearest first (the point itself not listed).
    normals : ndarray, shape (n, 3)
        Unit normal of every point (NaN: its plane does not count; a point with fewer than
        OWN_SHEET_RANK neighbors that have one is not flagged).
    reach : ndarray, shape (n,)
        Distance of every point to its ISOLATION_K-th nearest neighbor: a neighbor farther
        from p than OWN_SHEET_REACH times its own does not count.
    excluded : ndarray, shape (n,), bool
        Points whose planes do not count (outliers already found).
    limit : float
        Largest distance of p from a neighbor's tangent plane for p to lie on its sheet.
    out : ndarray, shape (m,), bool
        Output flags.
    """
    k = min(OWN_SHEET_K, nbr.shape[1])
    for j in prange(query.shape[0]):
        p = query[j]
        near = 0
        planes = 0  # neighbors with a plane to judge by
        for i in range(k):
            q = nbr[j, i]
            if excluded[q] or not np.isfinite(normals[q, 0]):
                continue
            planes += 1
            h = 0.0
            r2 = 0.0
            for d in range(3):
                u = points[p, d] - points[q, d]
                h += u * normals[q, d]
                r2 += u * u
            if abs(h) <= limit and r2 <= (OWN_SHEET_REACH * reach[q]) ** 2:
                near += 1
        # Too few planes (degenerate neighborhoods around) say nothing: not flagged.
        out[j] = planes >= OWN_SHEET_RANK and near < OWN_SHEET_RANK


def isolated(points: np.ndarray, tree: tuple, reach: np.ndarray, out: np.ndarray,
             rows: np.ndarray | None = None) -> None:
    """Flag the points whose ISOLATION_K-th neighbor is far farther than their neighbors' are.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    tree : tuple
        :func:`~curvature.neighborhoods.kdtree.build_tree` over ``points``.
    reach : ndarray, shape (m,)
        Distance of every tested point to its ISOLATION_K-th nearest neighbor.
    out : ndarray, shape (m,), bool
        Set True (in place) where a tested point is isolated; never cleared.
    rows : ndarray, shape (m,), int64, optional
        The tested points (default: all, m = n). The neighbors' own reach is then measured
        where it is needed, for the few points that pass the filter below.
    """
    from ..neighborhoods.kdtree import knn_parallel

    # Only points beyond half the threshold of the tested points' median can pass it against
    # their neighbors' unless those are denser than the cloud by more than 2: a cheap filter.
    cand = np.flatnonzero(reach > 0.5 * ISOLATION * np.median(reach)).astype(np.int64)
    k = min(ISOLATION_K, points.shape[0] - 1)
    if cand.size == 0 or k < 1:
        return
    ids = cand if rows is None else rows[cand]
    nbr = np.empty((cand.size, k), np.int64)
    knn_parallel(points, tree, ids, k, nbr, np.empty((cand.size, k)))
    if rows is None:
        near = reach[nbr]
    else:
        uniq, inv = np.unique(nbr, return_inverse=True)
        d2 = np.empty((uniq.size, k))
        knn_parallel(points, tree, uniq, k, np.empty((uniq.size, k), np.int64), d2)
        near = np.sqrt(d2[:, k - 1])[inv.reshape(nbr.shape)]
    local = np.median(near, axis=1)
    out[cand[reach[cand] > ISOLATION * local]] = True
