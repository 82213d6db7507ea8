"""Per-anchor neighborhood size: the largest fit that still agrees with the smaller ones.

A fixed neighborhood size trades bias against noise once for the whole cloud: large fits
average noise away on flat faces but blur fillets, corners and leading edges and reach across
thin walls; small fits follow features but are noisy. Here every anchor fits Monge quadrics
and normal-constrained quadrics (:mod:`curvature.fitting.normal_quadric`) on nested prefixes of
its sorted neighbor list (the ``ladder``: 24, 48, 96, 192 neighbors) beside the full fits of
:func:`~curvature.fitting.normal_field.nfr_anchor_fits` (both models) over 384 and 768 (the
``tops``; every second of the 768), and keeps one of them by the
rule of Lepski (Lepski, Mammen & Spokoiny, Ann. Statist. 25 (1997)), the pairwise form of the
intersection of confidence intervals rule (Goldenshluger & Nemirovski, Math. Methods Statist. 6
(1997)):

* the small rungs are positional Monge fits (a quadratic height function over the anchor's PCA
  plane, corrected to be exact on spheres and cylinders: ``circular`` in
  :func:`~curvature.fitting.kernels.fit_monge`): the stage-1 normals are PCA normals over 48
  neighbors, smoothed across any feature narrower than that, so a fit to them cannot be sharper than
  they are (on a fillet of 6.5 spacings the normal fits read 3.4 for 5 at any size, Monge over 24
  points 5.15); the larger rungs fit the normal-constrained quadric, which averages noise better;
* every scale s gives principal curvatures k1_s, k2_s at the anchor and a standard error
  ``sigma_s = calib_s * d_s / (h_s**2 * sqrt(s))``, with d_s the fit's RMS distance of its
  points to the fitted surface (noise plus whatever the model cannot follow) and h_s their RMS
  distance from the anchor: the error of a curvature read off a least-squares surface over s
  points spread over radius h with residual d. ``calib_s`` (in :data:`RUNGS` and
  :data:`TOPS`) makes sigma_s the measured error on noisy planes and spheres (docs/accuracy.md);
* the largest fit is kept whose k1 and k2 agree with those of every smaller fit within ``gamma
  (sigma_s + sigma_r)`` (Lepski's rule: its bias is not visible above the noise of any smaller fit;
  the 24-point fit only checks the 48-point one), and whose sigma is at most :data:`SIGMA_GROWTH`
  times the smallest below it: a fit that reached across a thin wall or over an edge has a large
  residual distance, and so a large sigma, even while its wide interval still overlaps the others.

The kept model is written in the same arrays as ``nfr_anchor_fits`` so that
:func:`~curvature.fitting.normal_field.nfr_from_anchors` reads it unchanged.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .kernels import MAX_FOOT_DIST, fit_monge, gather_local, principal_axes, spans_surface
from .normal_field import nfr_anchor_fits_one, supported
from .normal_quadric import N_QUAD, curvature_from_quadric, regress_normal_quadric
from .quadric import OK, foot_point, gradient_at, sampson_rms, shape_operator

__all__ = ["DEFAULT_GAMMA", "KIND_MONGE", "KIND_NORMAL_QUADRIC", "RUNGS", "SIGMA_FLOOR", "TOPS",
           "ladder_estimates", "multiscale_anchor_fits", "pass_rungs", "scale_sigma"]

#: Rung models: a positional Monge quadric, the normal-constrained quadric, or a Monge
#: quadric with CIRCULAR_ROUNDS of the circular correction (kernels.fit_monge). On a filleted
#: box at 0.05 % noise the correction cut the 48-point rung's mean |k1| / |k2| error at the
#: corners from 0.53 / 0.24 to 0.14 / 0.22, and on a blade's leading edge (k = 20, 0.1 %)
#: from 3.8 to 0.9; on planes its calibration is within 5 % of the plain fit's.
KIND_MONGE = 0
KIND_NORMAL_QUADRIC = 1
KIND_MONGE_CIRCULAR = 2
CIRCULAR_ROUNDS = 3
#: The rungs of each pass, ``(neighbors, model, calibration)``: prefix fits tried below the
#: tops. The calibration is the standard error per unit of d / (h^2 sqrt(s)): RMS curvature
#: error over that RMS measured on noisy planes, spheres and cylinders (0.1 to 0.5 % noise,
#: 20,000 points; benchmarks/calibrate_scales.py), constant within about 15 % across shapes
#: and noise; the Monge rungs' errors are larger than their residuals say because the fit sees
#: few points per unknown. Pass 1 ("refine") only refines normals: Monge rungs would tilt them
#: by their noisy curvature over a cell's width.
RUNGS = {
    "refine": ((96, KIND_NORMAL_QUADRIC, 1.9), (192, KIND_NORMAL_QUADRIC, 2.6)),
    "fit": ((24, KIND_MONGE_CIRCULAR, 6.7), (48, KIND_MONGE_CIRCULAR, 5.5),
            (96, KIND_NORMAL_QUADRIC, 1.9), (192, KIND_NORMAL_QUADRIC, 2.6)),
}
#: The default tops of each pass, ``(neighbors, calibration)``: full fits (both models)
#: above the ladder. A top fits every ``stride``-th of its sorted neighbors, ``stride =
#: max(1, size // TOP_POINTS)``: stage-1 normals of nearby points share most of their
#: neighbors, so every second one of 768 carries nearly all their information (a
#: 10,000-point sphere at 0.5 % noise: 0.0137 against 0.0133 with all 768) at the cost of a
#: 384-neighbor fit. Calibrations as the rungs'; the strided top's is lower since its
#: neighbors' normals are fewer than its patch's points, and set so that its standard errors
#: match the errors of the results on noisy spheres (median error / 0.674 over the median
#: standard error: 0.73 with 4.4, about 1 with 3.3).
TOPS = {"refine": ((384, 4.4), (768, 3.3)), "fit": ((384, 4.4), (768, 3.3))}
TOP_POINTS = 384
#: A default top is kept below ``k`` only when it is at most this fraction of ``k``.
TOP_GAP = 1.0 / 1.5
#: Agreement tolerance in standard errors. 5 (before the circular rungs) let the wider
#: normal fits' bias at corners and fillets pass (filleted box at 0.05 %: corners 1.02 with
#: the circular rungs, 0.45 with 3.5, mean of the larger of the k1 and k2 errors); 3.5 costs
#: about 10 % on noisy smooth shapes (10,000-point sphere at 0.5 %: 0.0142 -> 0.0156), 3
#: already 40 %.
DEFAULT_GAMMA = 3.5
#: Agreement a wider top needs with the top below it, in combined standard errors.
TOP_AGREEMENT = 1.5
#: A fit whose sigma exceeds the smallest sigma below it by more than this is turned down.
SIGMA_GROWTH = 2.0
#: A kept fit's curvature farther than this many combined standard errors from a smaller
#: fit's shows a bias of the kept fit: the excess is its estimate (``bias`` output).
BIAS_SLACK = 1.5
#: Relative floor of sigma (times 1 / h): noise-free fits are exact only up to rounding.
SIGMA_FLOOR = 1e-7
# A foot point farther than this many fit units from the anchor means the fit missed it.
FOOT_LIMIT = 2.0


def pass_rungs(k: int, stage: str, fallback: int | None = None) -> tuple[np.ndarray, ...]:
    """The ladder and tops of one pass of an estimator whose largest fit is ``k``.

    Tops: the default ones at most :data:`TOP_GAP` times ``k``, then ``k`` itself, plus one
    at ``fallback`` when ``k`` exceeds it and no top lies between ``TOP_GAP`` times it
    and it (strides: :data:`TOP_POINTS`; calibration: that of the smallest default top not
    below it, or of the largest). The top at ``fallback`` is what a wider top
    falls back to where it is turned down: without it, on a small torus, the next fit below
    is a 192-neighbor quadric, biased there.

    Parameters
    ----------
    k : int
        The largest fit's neighbors.
    stage : str
        ``"refine"`` (pass 1) or ``"fit"`` (pass 2).
    fallback : int, optional
        A size that must have a top of its own (default ``k``).

    Returns
    -------
    ladder, kinds : ndarray, shape (l,), int64
    tops, strides : ndarray, shape (t,), int64
    calib : ndarray, shape (l + t,)
        Of the rungs, then of the tops.
    """
    rungs, defaults = RUNGS[stage], TOPS[stage]
    limit = k if fallback is None else min(fallback, k)
    sizes = [t[0] for t in defaults if t[0] <= TOP_GAP * k] + [k]
    if not any(TOP_GAP * limit <= size <= limit for size in sizes):
        sizes = sorted(set(sizes) | {limit})
    tops = []
    for size in sizes:
        calib = next((t[1] for t in defaults if t[0] >= size), defaults[-1][1])
        tops.append((size, max(1, size // TOP_POINTS), calib))
    ladder = [r for r in rungs if r[0] < tops[0][0]]
    return (np.asarray([r[0] for r in ladder], np.int64),
            np.asarray([r[1] for r in ladder], np.int64),
            np.asarray([t[0] for t in tops], np.int64),
            np.asarray([t[1] for t in tops], np.int64),
            np.asarray([r[2] for r in ladder] + [t[2] for t in tops], np.float64))


@njit(cache=True)
def scale_sigma(distance, h, count, calib):
    """Standard error of a curvature read off a fit (module docstring), in 1 / length."""
    return max(calib * distance / (h * h * np.sqrt(count)), SIGMA_FLOOR / h)


@njit(cache=True)
def _monge_rung(points, field, p, nbr, quad, circular):
    """Monge quadric over ``p`` and ``nbr`` (``circular`` rounds of the circular correction),
    packed like the normal-constrained quadric.

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
    a, b, c, ok = fit_monge(xs, axes, circular)
    if not ok:
        return 2, h, np.nan, np.nan, np.nan
    x0, found = foot_point(a, b, c, MAX_FOOT_DIST)
    if not found:
        return 3, h, np.nan, np.nan, np.nan
    g = gradient_at(a, b, x0)
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
        if kinds[li] != KIND_NORMAL_QUADRIC:
            rounds = CIRCULAR_ROUNDS if kinds[li] == KIND_MONGE_CIRCULAR else 0
            st, h, d, c1, c2 = _monge_rung(points, field, p, nbr[:s], quads[li], rounds)
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
def _lepski(est, sg, gamma, growth, first_top):
    """Index of the fit to keep: the largest whose k1 and k2 agree with those of every smaller
    fit within ``gamma`` times the sum of both sigmas, and whose sigma is at most ``growth``
    times the smallest sigma below it (-1 when none is usable). A top above the first
    (index above ``first_top``) must also agree with the top just below it within
    :data:`TOP_AGREEMENT` times their combined sigma: the two fit the same model to nested
    patches, so their noise is shared and a small difference already shows a bias.

    Each candidate is compared with every smaller rung directly, not with a running intersection, so
    one chance disagreement between two noisy small fits does not stop the selection at the smallest
    of them; and the smallest rung (24 points, the noisiest) can only turn down the next: alone it
    stopped every wider fit where it was off by chance (a 10,000-point plane at 0.1 % noise, p99.9
    of |k| 1.9 with it, 1.3 without, max 9.6 and 2.8), while at fillets and corners the 48-point
    rung sees the same biases. The growth test turns down a large fit whose residual jumped (it
    reached across a thin wall or over an edge) even while its wide interval still overlaps the
    others.
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
            if r == 0 and c > 1:
                continue
            tol = gamma * (sg[r] + sg[c])
            if abs(est[c, 1] - est[r, 1]) > tol or abs(est[c, 2] - est[r, 2]) > tol:
                agrees = False
                break
        if agrees and c > first_top and np.isfinite(sg[c - 1]):
            tol = TOP_AGREEMENT * np.sqrt(sg[c] * sg[c] + sg[c - 1] * sg[c - 1])
            if abs(est[c, 1] - est[c - 1, 1]) > tol or abs(est[c, 2] - est[c - 1, 2]) > tol:
                agrees = False
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
                           tops, strides, gamma, growth, calib, coef, scale, frame, quad,
                           quad_scale, model, residual, status, chosen, sigma, bias):
    """Fits at anchors with the neighborhood size chosen per anchor (module docstring).

    Parameters
    ----------
    points, field, anchors, indptr, indices, nfr_ratio
        As for :func:`~curvature.fitting.normal_field.nfr_anchor_fits`; every anchor's
        neighbor list must be sorted by distance.
    ladder, kinds : ndarray, shape (l,), int64
        Increasing neighbor counts (the anchor takes part besides) tried below the tops, and
        their models.
    tops, strides : ndarray, shape (t,), int64
        Increasing neighbor counts of the full fits (both models, as ``nfr_anchor_fits``)
        above the ladder, and the stride of each over the sorted list: a top of size s and
        stride r fits every r-th of the s nearest neighbors (a wide patch at the cost of a
        small fit). A top not below the list's length fits the whole list.
    gamma : float
        Agreement tolerance in standard errors.
    growth : float
        Largest ratio of a kept fit's sigma to the smallest sigma of the fits below it.
    calib : ndarray, shape (l + t,)
        Standard-error calibration of every rung and of every top.
    coef, scale, frame, quad, quad_scale, model, residual, status
        Outputs as for ``nfr_anchor_fits``: the kept model.
    chosen : ndarray, shape (a,), int64
        Output: neighbors of the kept fit (the anchor takes part besides): the patch's size,
        strided tops included.
    sigma : ndarray, shape (a,)
        Output: the kept fit's standard error of curvature (inf when none was usable).
    bias : ndarray, shape (a,)
        Output: the kept fit's bias as the smaller fits show it: the largest excess of
        ``|k_kept - k_r|`` (k1 or k2) over ``BIAS_SLACK`` times their combined standard
        errors, over every usable smaller rung r (0 when none disagrees).
    """
    levels = ladder.shape[0]
    ntop = tops.shape[0]
    for j in prange(anchors.shape[0]):
        p = anchors[j]
        nbr = indices[indptr[j]:indptr[j + 1]]
        full = nbr.shape[0]
        quads = np.empty((levels, N_QUAD))
        est = np.empty((levels + ntop, 5))
        ladder_estimates(points, field, p, nbr, ladder, kinds, quads, est)
        # Every top's full fit (both models) into scratch rows; the kept one is copied out.
        t_coef = np.empty((ntop,) + coef.shape[1:])
        t_quad = np.empty((ntop, N_QUAD))
        t_frame = np.empty((ntop, 3, 3))
        t_scale, t_qscale, t_resid = np.empty(ntop), np.empty(ntop), np.empty(ntop)
        t_model, t_status = np.empty(ntop, np.int8), np.empty(ntop, np.int8)
        sizes = np.empty(levels + ntop, np.int64)
        sizes[:levels] = ladder
        for t in range(ntop):
            size = min(tops[t], full)
            sizes[levels + t] = size
            row = levels + t
            est[row, 0] = 0.0
            if t > 0 and size <= sizes[row - 1]:
                t_status[t] = -1
                continue  # the list is shorter than this top: the one below already fits it
            if t > 0 and est[row - 1, 0] != 1.0:
                # Where the smaller top failed or was not supported (duplicates, a line, an
                # isolated cluster) a wider one fits whatever else it reaches: no wider top.
                t_status[t] = -1
                continue
            sub = nbr[:size:strides[t]]
            fk1, fk2, fd, fh = nfr_anchor_fits_one(points, field, p, sub, nfr_ratio, t_coef[t],
                                                   t_quad[t], t_frame[t], t, t_scale,
                                                   t_qscale, t_model, t_resid, t_status)
            if t_status[t] == OK and supported(fk1, fk2, fh):
                est[row, 0] = 1.0
                est[row, 1], est[row, 2], est[row, 3], est[row, 4] = fk1, fk2, fd, fh
        sg = np.full(levels + ntop, np.inf)
        for li in range(levels + ntop):
            if est[li, 0] == 1.0:
                s = sizes[li]
                if li >= levels:
                    s = (s + strides[li - levels] - 1) // strides[li - levels]
                sg[li] = scale_sigma(est[li, 3], est[li, 4], s, calib[li])
        best = _lepski(est, sg, gamma, growth, levels)
        # The top to report when nothing is usable: the largest that fitted, else the first
        # (its status stands; a wider top is only tried where the one below it was usable).
        keep = ntop - 1
        while keep > 0 and t_status[keep] != OK:
            keep -= 1
        if best >= levels:
            keep = best - levels
        for r in range(coef.shape[1]):
            for c in range(coef.shape[2]):
                coef[j, r, c] = t_coef[keep, r, c]
        for r in range(N_QUAD):
            quad[j, r] = t_quad[keep, r]
        for r in range(3):
            for c in range(3):
                frame[j, r, c] = t_frame[keep, r, c]
        scale[j], quad_scale[j], model[j] = t_scale[keep], t_qscale[keep], t_model[keep]
        residual[j], status[j] = t_resid[keep], t_status[keep]
        chosen[j] = sizes[levels + keep]
        sigma[j] = np.inf
        bias[j] = 0.0
        if best < 0:
            continue  # nothing usable: the largest top's status stands
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
