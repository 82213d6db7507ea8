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

The PCA plane of a one-sided neighborhood is not even the tangent plane at the centroid
where the patch's width changes with the distance from the point (a half-disk of a cylinder
cut across its axis narrows around the tube, so its mean height drifts along the axis and
the plane tilts: 0.015 rad on a unit cylinder at 48 of 6,000 points). The moved normals are
therefore those of quadratic height fits, at the centroid (:func:`centroid_normals`): a
cylinder's band within 0.3 of its cut ends' interior limit read k2 (true 0) 0.025 with the
PCA normals, 0.003 with these (10,000 points, 0.1 % view noise).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .linalg import cholesky, solve_lower, solve_upper_t
from .quadric import tangent_basis_xyz

__all__ = ["SHIFT_FROM", "SHIFT_RAMP", "border_offsets", "centroid_normals"]

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


@njit(parallel=True, cache=True)
def centroid_normals(points, query, nbr, normals, out):
    """Normals of the tangent planes at the neighborhoods' centroids, from quadratic height
    fits: where a PCA normal is read at its centroid (:func:`border_offsets`) it should be
    the tangent plane's there, and a one-sided PCA plane is not even that. Over a half-disk
    of a cylinder, cut across its axis, the patch narrows around the tube away from the
    point, so its mean height changes along the axis and the plane tilts along it; a height
    ``c + b . u + u' A u`` in coordinates about the centroid carries that change in ``A`` and
    leaves ``b``, the slope at the centroid.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    query : ndarray, shape (m,), int64
    nbr : ndarray, shape (m, k), int
        The PCA neighbors (the query point not listed; it takes part).
    normals : ndarray, shape (m, 3)
        The PCA normals (the fits' frames; the results keep their sides).
    out : ndarray, shape (m, 3)
        Output unit normals; the PCA normal where the fit is degenerate.
    """
    k = nbr.shape[1]
    for j in prange(query.shape[0]):
        n0, n1, n2 = normals[j, 0], normals[j, 1], normals[j, 2]
        out[j, 0], out[j, 1], out[j, 2] = n0, n1, n2
        if not (np.isfinite(n0) and np.isfinite(n1) and np.isfinite(n2)):
            continue
        a0, a1, a2, b0, b1, b2 = tangent_basis_xyz(n0, n1, n2)
        m = k + 1
        local = np.empty((m, 3))
        q = query[j]
        for i in range(m):
            r = q if i == 0 else nbr[j, i - 1]
            x = points[r, 0] - points[q, 0]
            y = points[r, 1] - points[q, 1]
            z = points[r, 2] - points[q, 2]
            local[i, 0] = x * a0 + y * a1 + z * a2
            local[i, 1] = x * b0 + y * b1 + z * b2
            local[i, 2] = x * n0 + y * n1 + z * n2
        # About the centroid, in units of the patch's RMS radius (conditioning only).
        for t in range(3):
            mean = 0.0
            for i in range(m):
                mean += local[i, t]
            mean /= m
            for i in range(m):
                local[i, t] -= mean
        ss = 0.0
        for i in range(m):
            ss += local[i, 0] * local[i, 0] + local[i, 1] * local[i, 1]
        unit = np.sqrt(ss / m)
        if not unit > 0.0:
            continue
        gram = np.zeros((6, 6))
        rhs = np.zeros(6)
        row = np.empty(6)
        for i in range(m):
            u, v = local[i, 0] / unit, local[i, 1] / unit
            row[0], row[1], row[2], row[3], row[4], row[5] = 1.0, u, v, u * u, u * v, v * v
            for r in range(6):
                rhs[r] += row[r] * local[i, 2] / unit
                for c in range(6):
                    gram[r, c] += row[r] * row[c]
        lower, ok = cholesky(gram, 1e-10)
        if not ok:
            continue
        coef = solve_upper_t(lower, solve_lower(lower, rhs))
        s0, s1 = coef[1], coef[2]  # the height's slope at the centroid
        c0 = n0 - s0 * a0 - s1 * b0
        c1 = n1 - s0 * a1 - s1 * b1
        c2 = n2 - s0 * a2 - s1 * b2
        norm = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
        out[j, 0], out[j, 1], out[j, 2] = c0 / norm, c1 / norm, c2 / norm
