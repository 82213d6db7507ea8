"""Points that lie off the surface their neighbors describe (scanner outliers).

A scan's outliers (mixed pixels, reflections, dust) sit far from the surface compared with how
thick the surface's own sample is. For every point p with unit normal n (stage-1 PCA) and
neighbors q_i, the offset of p from the neighbors' centroid c along n is compared with the
neighbors' own spread along n (their RMS offset from c): p is an outlier when

    |(p - c) . n| > OUTLIER_SIGMAS * thickness + OUTLIER_FLOOR * spacing  (4 and 0.2).

The floor keeps noise-free clouds (thickness 0) from flagging rounding. Curvature sag raises the
thickness and the offset alike, so fillets are not flagged. Outliers' normals are left out of
every normal fit and their positions out of the positional fits, so they cannot drag a fit;
they still get a result of their own.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["OUTLIER_FLOOR", "OUTLIER_SIGMAS", "off_surface"]

#: Offsets beyond this many neighbor thicknesses are outliers.
OUTLIER_SIGMAS = 4.0
#: Plus this share of the point spacing (noise-free clouds have no thickness).
OUTLIER_FLOOR = 0.2


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
