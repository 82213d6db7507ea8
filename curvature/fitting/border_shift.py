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

from .kernels import fit_monge, gather_local, principal_axes, spans_surface
from .quadric import gradient_at

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
    point, so its mean height changes along the axis and the plane tilts along it; the height
    quadric of the Monge fits (:func:`~curvature.fitting.kernels.fit_monge`) carries that change
    in its quadratic terms, and its slope at the centroid is the tangent plane's there.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    query : ndarray, shape (m,), int64
    nbr : ndarray, shape (m, k), int
        The PCA neighbors (the query point not listed; it takes part).
    normals : ndarray, shape (m, 3)
        The PCA normals: the results keep their sides (NaN stays NaN).
    out : ndarray, shape (m, 3)
        Output unit normals; the PCA normal where the fit is degenerate.
    """
    for j in prange(query.shape[0]):
        n0, n1, n2 = normals[j, 0], normals[j, 1], normals[j, 2]
        out[j, 0], out[j, 1], out[j, 2] = n0, n1, n2
        if not (np.isfinite(n0) and np.isfinite(n1) and np.isfinite(n2)):
            continue
        # The height quadric of the Monge fits, in the patch's PCA frame; its gradient at
        # the centroid is that of h(u, v) - w there (no w^2 term without the correction).
        xs, scale = gather_local(points, query[j], nbr[j], True)
        if not scale > 0.0:
            continue
        w, axes = principal_axes(xs)
        if not spans_surface(w):
            continue
        a, b, _, ok = fit_monge(xs, axes, 0)
        if not ok:
            continue
        centroid = np.zeros(3)
        for i in range(xs.shape[0]):
            for t in range(3):
                centroid[t] += xs[i, t]
        g = gradient_at(a, b, centroid / xs.shape[0])
        norm = np.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
        if g[0] * n0 + g[1] * n1 + g[2] * n2 < 0.0:
            norm = -norm
        out[j, 0], out[j, 1], out[j, 2] = g[0] / norm, g[1] / norm, g[2] / norm
