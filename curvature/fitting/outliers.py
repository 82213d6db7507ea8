"""Points that lie off the surface their neighbors describe (scanner outliers).

A scan's outliers (mixed pixels, reflections, dust) sit far from the surface compared with how
thick the surface's own sample is. For every point p with unit normal n (stage-1 PCA) and
neighbors q_i, the offset of p from the neighbors' centroid c along n is compared with the
neighbors' own spread along n (their RMS offset from c): p is an outlier when

    |(p - c) . n| > OUTLIER_SIGMAS * thickness + OUTLIER_FLOOR * spacing  (4 and 0.2).

The floor keeps noise-free clouds (thickness 0) from flagging rounding. Curvature sag raises the
thickness and the offset alike, so fillets are not flagged.

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

__all__ = ["ISOLATION", "ISOLATION_K", "OUTLIER_FLOOR", "OUTLIER_SIGMAS", "isolated", "off_surface"]

#: Offsets beyond this many neighbor thicknesses are outliers.
OUTLIER_SIGMAS = 4.0
#: Plus this share of the point spacing (noise-free clouds have no thickness).
OUTLIER_FLOOR = 0.2
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
