"""Per-anchor neighborhood size: the largest fit that still agrees with the smaller ones.

A fixed neighborhood size trades bias against noise once for the whole cloud: large fits
average noise away on flat faces but blur fillets, corners and leading edges and reach across
thin walls; small fits follow features but are noisy. Here every anchor fits Monge quadrics
and normal-constrained quadrics (:mod:`curvature.fitting.normal_quadric`) on nested prefixes of
its sorted neighbor list (the ``ladder``: 24, 48, 96, 192 neighbors) beside the full-size fit of
:func:`~curvature.fitting.normal_field.nfr_anchor_fits`, and keeps one of them by the
rule of Lepski (Lepski, Mammen & Spokoiny, Ann. Statist. 25 (1997)), the pairwise form of the
intersection of confidence intervals rule (Goldenshluger & Nemirovski, Math. Methods Statist. 6
(1997)):

* the small rungs are positional Monge fits (a quadratic height function over the anchor's
  PCA plane): the stage-1 normals are PCA normals over 48 neighbors, smoothed across any
  feature narrower than that, so a fit to them cannot be sharper than they are (on a fillet of
  6.5 spacings the normal fits read 3.4 for 5 at any size, Monge over 24 points 5.15); the
  larger rungs fit the normal-constrained quadric, which averages noise better;
* every scale s gives principal curvatures k1_s, k2_s at the anchor and a standard error
  ``sigma_s = calib_s * d_s / (h_s**2 * sqrt(s))``, with d_s the fit's RMS distance of its
  points to the fitted surface (noise plus whatever the model cannot follow) and h_s their RMS
  distance from the anchor: the error of a curvature read off a least-squares surface over s
  points spread over radius h with residual d. ``calib_s`` (:data:`CALIBRATION`) makes sigma_s
  the measured error on noisy planes and spheres (docs/accuracy.md);
* the largest fit is kept whose k1 and k2 agree with those of every smaller fit within
  ``gamma (sigma_s + sigma_r)`` (Lepski's rule: its bias is not visible above the noise of
  any smaller fit), and whose sigma is at most :data:`SIGMA_GROWTH` times the smallest below
  it: a fit that reached across a thin wall or over an edge has a large residual distance,
  and so a large sigma, even while its wide interval still overlaps the others.

The kept model is written in the same arrays as ``nfr_anchor_fits`` so that
:func:`~curvature.fitting.normal_field.nfr_from_anchors` reads it unchanged.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .kernels import MAX_FOOT_DIST, fit_monge, gather_local, principal_axes, spans_surface
from .normal_field import nfr_anchor_fits_one, supported
from .normal_quadric import N_QUAD, curvature_from_quadric, regress_normal_quadric
from .quadric import OK, foot_point, sampson_rms, shape_operator

__all__ = ["CALIBRATION", "DEFAULT_GAMMA", "DEFAULT_KINDS", "DEFAULT_LADDER", "KIND_MONGE",
           "KIND_NORMAL_QUADRIC", "SIGMA_FLOOR", "ladder_estimates", "multiscale_anchor_fits",
           "scale_sigma"]

#: Rung models: a positional Monge quadric, or the normal-constrained quadric.
KIND_MONGE = 0
KIND_NORMAL_QUADRIC = 1
#: Prefix sizes tried below the full neighborhood (only those smaller than it are used), and
#: the model of each.
DEFAULT_LADDER = (24, 48, 96, 192)
DEFAULT_KINDS = (KIND_MONGE, KIND_MONGE, KIND_NORMAL_QUADRIC, KIND_NORMAL_QUADRIC)
#: Agreement tolerance in standard errors.
DEFAULT_GAMMA = 5.0
#: Standard error per unit of d / (h^2 sqrt(s)) of each rung, and of the full-size fit (last
#: entry): RMS curvature error over that RMS measured on noisy planes, spheres and cylinders
#: (0.1 to 0.5 % noise, 20,000 points; benchmarks/calibrate_scales.py). Constant within about
#: 15 % across shapes and noise; the Monge rungs' errors are larger than their residuals say
#: because the fit sees few points per unknown.
CALIBRATION = (7.0, 5.8, 1.9, 2.6, 4.4)
#: A fit whose sigma exceeds the smallest sigma below it by more than this is turned down.
SIGMA_GROWTH = 2.0
#: A kept fit's curvature farther than this many combined standard errors from a smaller
#: fit's shows a bias of the kept fit: the excess is its estimate (``bias`` output).
BIAS_SLACK = 1.5
#: Relative floor of sigma (times 1 / h): noise-free fits are exact only up to rounding.
SIGMA_FLOOR = 1e-7
# A foot point farther than this many fit units from the anchor means the fit missed it.
FOOT_LIMIT = 2.0


@njit(cache=True)
def scale_sigma(distance, h, count, calib):
    """Standard error of a curvature read off a fit (module docstring), in 1 / length."""
    return max(calib * distance / (h * h * np.sqrt(count)), SIGMA_FLOOR / h)


@njit(cache=True)
def _monge_rung(points, field, p, nbr, quad):
    """Monge quadric over ``p`` and ``nbr``, packed like the normal-constrained quadric.

    Returns
    -------
    status, h, distance, k1, k2
        Fit status, coordinate unit, RMS residual distance (input units) and the curvatures
        at p's foot point, signed against ``field[p]`` (the quadric is negated to agree).
    """
    # Neighbors without a normal are outliers (curvature.fitting.outliers): left out.
    keep = np.empty(nbr.shape[0], nbr.dtype)
    count = 0
    for i in range(nbr.shape[0]):
        if np.isfinite(field[nbr[i], 0]):
            keep[count] = nbr[i]
            count += 1
    if count < 6:
        return 1, 0.0, np.nan, np.nan, np.nan
    xs, h = gather_local(points, p, keep[:count], True)
    if not h > 0.0:
        return 2, 0.0, np.nan, np.nan, np.nan
    w, axes = principal_axes(xs)
    if not spans_surface(w):
        return 2, h, np.nan, np.nan, np.nan
    a, b, c, ok = fit_monge(xs, axes)
    if not ok:
        return 2, h, np.nan, np.nan, np.nan
    x0, found = foot_point(a, b, c, MAX_FOOT_DIST)
    if not found:
        return 3, h, np.nan, np.nan, np.nan
    g = 2.0 * (a @ x0) + b
    n_p = field[p]
    if g[0] * n_p[0] + g[1] * n_p[1] + g[2] * n_p[2] < 0.0:
        a, b, c, g = -a, -b, -c, -g
    c1, c2, _, _, _ = shape_operator(g, 2.0 * a)
    quad[0], quad[1], quad[2] = a[0, 0], a[1, 1], a[2, 2]
    quad[3], quad[4], quad[5] = a[0, 1], a[0, 2], a[1, 2]
    quad[6], quad[7], quad[8] = b[0], b[1], b[2]
    quad[9] = c
    return OK, h, sampson_rms(a, b, c, xs) * h, c1 / h, c2 / h


@njit(cache=True)
def ladder_estimates(points, field, p, nbr, ladder, kinds, quads, out):
    """Every rung's fit at one anchor (rungs not smaller than the full list are skipped).

    Parameters
    ----------
    points, field : ndarray, shape (n, 3)
    p : int
    nbr : ndarray, shape (k,)
        Neighbors of p sorted by distance (p not listed).
    ladder, kinds : ndarray, shape (l,), int64
    quads : ndarray, shape (l, N_QUAD)
        Output: each rung's packed quadric.
    out : ndarray, shape (l, 5)
        Output per rung: ok (1 or 0), k1, k2, residual distance, h (the quadric's unit).
    """
    origin = np.zeros(3)
    for li in range(ladder.shape[0]):
        out[li, 0] = 0.0
        s = ladder[li]
        if s >= nbr.shape[0]:
            continue
        if kinds[li] == KIND_MONGE:
            st, h, d, c1, c2 = _monge_rung(points, field, p, nbr[:s], quads[li])
        else:
            st, h, _, d = regress_normal_quadric(points, field, p, nbr[:s], True, quads[li])
            if st == OK:
                st, c1, c2, _, _, _ = curvature_from_quadric(quads[li], h, origin, FOOT_LIMIT)
        if st != OK or not supported(c1, c2, h):
            continue
        out[li, 0] = 1.0
        out[li, 1] = c1
        out[li, 2] = c2
        out[li, 3] = d
        out[li, 4] = h


@njit(cache=True)
def _lepski(est, sg, gamma, growth):
    """Index of the fit to keep: the largest whose k1 and k2 agree with those of every smaller
    fit within ``gamma`` times the sum of both sigmas, and whose sigma is at most ``growth``
    times the smallest sigma below it (-1 when none is usable).

    Each candidate is compared with every smaller rung directly, not with a running
    intersection, so one chance disagreement between two noisy small fits does not stop the
    selection at the smallest of them. The growth test turns down a large fit whose residual
    jumped (it reached across a thin wall or over an edge) even while its wide interval still
    overlaps the others.
    """
    count = est.shape[0]
    for c in range(count - 1, -1, -1):
        if not np.isfinite(sg[c]):
            continue
        agrees = True
        smallest = np.inf
        for r in range(c):
            if not np.isfinite(sg[r]):
                continue
            smallest = min(smallest, sg[r])
            tol = gamma * (sg[r] + sg[c])
            if abs(est[c, 1] - est[r, 1]) > tol or abs(est[c, 2] - est[r, 2]) > tol:
                agrees = False
                break
        if agrees and sg[c] <= growth * smallest:
            return c
    return -1


@njit(cache=True)
def _bias(est, sg, best):
    """Disagreement of fit ``best`` with the smaller usable fits beyond their errors."""
    out = 0.0
    for r in range(best):
        if not np.isfinite(sg[r]):
            continue
        slack = BIAS_SLACK * np.sqrt(sg[r] * sg[r] + sg[best] * sg[best])
        for i in (1, 2):
            out = max(out, abs(est[best, i] - est[r, i]) - slack)
    return out


@njit(parallel=True, cache=True)
def multiscale_anchor_fits(points, field, anchors, indptr, indices, nfr_ratio, ladder, kinds,
                           gamma, growth, calib, coef, scale, frame, quad, quad_scale, model,
                           residual, status, chosen, sigma, bias):
    """Fits at anchors with the neighborhood size chosen per anchor (module docstring).

    Parameters
    ----------
    points, field, anchors, indptr, indices, nfr_ratio
        As for :func:`~curvature.fitting.normal_field.nfr_anchor_fits`; every anchor's
        neighbor list must be sorted by distance.
    ladder, kinds : ndarray, shape (l,), int64
        Increasing neighbor counts (the anchor takes part besides) tried below the full list,
        and their models.
    gamma : float
        Agreement tolerance in standard errors.
    growth : float
        Largest ratio of a kept fit's sigma to the smallest sigma of the fits below it.
    calib : ndarray, shape (l + 1,)
        Standard-error calibration of every rung and of the full-size fit.
    coef, scale, frame, quad, quad_scale, model, residual, status
        Outputs as for ``nfr_anchor_fits``: the kept model.
    chosen : ndarray, shape (a,), int64
        Output: neighbors of the kept fit (the anchor takes part besides).
    sigma : ndarray, shape (a,)
        Output: the kept fit's standard error of curvature (inf when none was usable).
    bias : ndarray, shape (a,)
        Output: the kept fit's bias as the smaller fits show it: the largest excess of
        ``|k_kept - k_r|`` (k1 or k2) over ``BIAS_SLACK`` times their combined standard
        errors, over every usable smaller rung r (0 when none disagrees).
    """
    levels = ladder.shape[0]
    for j in prange(anchors.shape[0]):
        p = anchors[j]
        nbr = indices[indptr[j]:indptr[j + 1]]
        full = nbr.shape[0]
        quads = np.empty((levels, N_QUAD))
        est = np.empty((levels + 1, 5))
        ladder_estimates(points, field, p, nbr, ladder, kinds, quads, est)
        # The full-size fit (both models), as without scale selection, is the last rung.
        fk1, fk2, fd, fh = nfr_anchor_fits_one(points, field, p, nbr, nfr_ratio, coef[j],
                                               quad[j], frame[j], j, scale, quad_scale, model,
                                               residual, status)
        usable = status[j] == OK and supported(fk1, fk2, fh)
        est[levels, 0] = 1.0 if usable else 0.0
        est[levels, 1], est[levels, 2], est[levels, 3], est[levels, 4] = fk1, fk2, fd, fh
        chosen[j] = full
        sigma[j] = np.inf
        bias[j] = 0.0
        sg = np.full(levels + 1, np.inf)
        for li in range(levels + 1):
            if est[li, 0] == 1.0:
                s = full if li == levels else ladder[li]
                sg[li] = scale_sigma(est[li, 3], est[li, 4], s, calib[li])
        best = _lepski(est, sg, gamma, growth)
        if best < 0:
            continue  # nothing usable: the full fit's status stands
        sigma[j] = sg[best]
        bias[j] = _bias(est, sg, best)
        if best < levels:
            chosen[j] = ladder[best]
            for r in range(N_QUAD):
                quad[j, r] = quads[best, r]
            quad_scale[j] = est[best, 4]
            model[j] = 1  # MODEL_QUADRIC: read with curvature_from_quadric
            residual[j] = est[best, 3]
            status[j] = OK
