"""Where a PCA normal belongs at the cloud's border: its neighborhood's centroid, not the point.

The least-squares plane through a point's neighbors is, on a smooth surface, parallel to the
tangent plane at their centroid (exactly so for a quadric height function: the fitted slope of
``a x^2`` over points centred at ``x0`` is ``2 a x0``), not at the point. Inside a cloud the two
nearly coincide; at its border the neighbors lie to one side and the centroid sits about half a
neighborhood radius inward, so a normal read as the point's is tilted by the curvature times
that offset. The first pass of the default (:mod:`curvature.estimators.auto`) fits a normal
field to these normals at positions; moving each border point's normal to the tangential part
of its centroid offset removes that tilt to first order (a bicubic Bezier patch at 0.1 % noise,
docs/accuracy.md section 8: mean error of the band within 0.05-0.1 of its border 0.029 ->
0.020).

Only clearly one-sided neighborhoods move (:data:`SHIFT_FROM`): inside a randomly sampled
cloud the centroid's tangential offset is 0.03-0.15 of the neighborhood's radius (10th to
90th percentile, 48 neighbors) and moving those normals too changed the filleted box's
corners at 0.1 % noise by +7 %; at a border it reaches 0.4.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["SHIFT_FROM", "SHIFT_RAMP", "border_offsets"]

#: Tangential centroid offset, as a share of the distance to the farthest PCA neighbor, from
#: which a normal moves; it moves by the whole offset from SHIFT_FROM + SHIFT_RAMP on.
SHIFT_FROM = 0.2
SHIFT_RAMP = 0.1


@njit(parallel=True, cache=True)
def border_offsets(points, query, nbr, normals, radius, out):
    """Offset from each query point to where its PCA normal belongs (module docstring).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    query : ndarray, shape (m,), int64
    nbr : ndarray, shape (m, k), int
        The neighbors the normals were fitted to (the query point itself not listed; it is
        counted, as :func:`~curvature.fitting.normal_field.pca_normals` counts it).
    normals : ndarray, shape (m, 3)
        Unit normals of the query points (NaN where unknown: no offset).
    radius : ndarray, shape (m,)
        Distance to the farthest of ``nbr``.
    out : ndarray, shape (m, 3)
        Output: ``w t``, t the centroid's offset from the point with its component along the
        normal removed, ``w = clip((|t| / radius - SHIFT_FROM) / SHIFT_RAMP, 0, 1)``.
    """
    k = nbr.shape[1]
    for j in prange(query.shape[0]):
        out[j, 0] = out[j, 1] = out[j, 2] = 0.0
        n0, n1, n2 = normals[j, 0], normals[j, 1], normals[j, 2]
        if not (np.isfinite(n0) and np.isfinite(n1) and np.isfinite(n2)) or not radius[j] > 0.0:
            continue
        q = query[j]
        d0 = d1 = d2 = 0.0
        for i in range(k):
            r = nbr[j, i]
            d0 += points[r, 0] - points[q, 0]
            d1 += points[r, 1] - points[q, 1]
            d2 += points[r, 2] - points[q, 2]
        d0 /= k + 1  # the point itself, at offset 0, is the (k + 1)-th
        d1 /= k + 1
        d2 /= k + 1
        along = d0 * n0 + d1 * n1 + d2 * n2
        t0, t1, t2 = d0 - along * n0, d1 - along * n1, d2 - along * n2
        share = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2) / radius[j]
        w = min(1.0, max(0.0, (share - SHIFT_FROM) / SHIFT_RAMP))
        out[j, 0], out[j, 1], out[j, 2] = w * t0, w * t1, w * t2
