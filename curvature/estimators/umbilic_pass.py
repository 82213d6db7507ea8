"""The default's last pass on noisy clouds: sphere and cylinder fits where they read a point
better.

Flat faces and sphere-like corners bend alike in every direction; beside a feature the scale
selection keeps small quadric fits there (their wider fits reach onto the feature), and
those read three curvature terms from few points. A sphere fit of one curvature term
(:mod:`curvature.fitting.umbilic`) over as many points reads such a point better. Its tests
(an F test of k1 = k2, its residual against the noise, Lepski's rule over its sizes, a
likelihood-ratio test of the kept estimate against it on the same points where that
estimate is wider than a small rung, a standard error below the estimate's) leave every
other point as it was. Where no sphere does, a cylinder across the estimate's more curved
direction may (a fillet, a cylinder's side, where a wide quadric reads the circle's quartic
term as curvature), only where the points reject the estimate strongly; not at the points
the circles across rounded thin edges read (``cylinders``). Not run on dense clouds (their
thinned share's fits are read at every point) nor on clean ones (exact implicit fits).
"""

from __future__ import annotations

import numpy as np

from ..fitting.umbilic import CYLINDER_EXTRAS, SIZES, f_critical, reads_axis_flat, umbilic_fits
from ..status import Status
from ..uncertainty import OWN_STD_SCALE, with_floor

__all__ = ["CYLINDERS", "CYLINDER_SHARE", "SHORT_SHARE", "SHORT_SIZES", "TRIED_SHARE", "candidates",
           "umbilic_pass"]


#: Only estimates kept over at most this many times the largest sphere's neighbors are tried:
#: 1152, the widest fit on clouds quieter than ``wide_noise`` (``QUIET_K`` of
#: :mod:`~curvature.estimators.auto`); wider fits, on noisier clouds, already read far more
#: precisely than a sphere over 384. Until stop 52 it was 2: a 96,000-point filleted box at
#: 0.05 % noise kept 1152-point fits on its faces beside the fillets, biased by them more
#: than their standard error (0.014) shows; the 384-point spheres there, usable at 254 of
#: 400 sampled points, erred 0.026 against those fits' 0.068 (faces over regions of fixed
#: width 0.083 -> 0.067, in 1.15 to 1.25 times the time; docs/accuracy.md section 9,
#: step 30). Noisier clouds never keep 1152 (their ladder goes 768, 1536).
TRIED_SHARE = 3
#: The sizes (48, 96 and 192: a 192-neighbor list) an estimate kept over at most SHORT_SHARE
#: times the last of them is tried with; only the wider ones are tried with 384 too. With
#: 384 everywhere the bench's blade read its sides 5 % better (seeds 1 to 4), but the
#: 20,000-point blade took 1.23 times as long, a 96,000-point box 1.44 times, PCL's table
#: scan 1.15 times (this way 1.13, 1.29 and 1.02 times; docs/accuracy.md section 9, step 28).
SHORT_SIZES = 3
SHORT_SHARE = 2
#: ... and so are the estimates kept over at least this many times the short ladder's last
#: size (384) that read their less curved direction flat, where a cylinder may replace them
#: (added at stop 54): a fillet's middle keeps 384-point quadrics, which read its circle's
#: quartic term as curvature, and only a 384-point cylinder is precise enough to show that.
#: The 96,000-point filleted box at 0.05 % noise read its fillets 0.152 -> 0.125 (mean of the
#: larger error, regions of fixed width; those more than 4 plan spacings from a jump 0.148 ->
#: 0.106), the bench's blade its crest 7.9 % better, PCL's table scan in 1.03 times the time.
#: With 1 (the estimates kept over 192 too) the bench's parts gained a little more (the
#: 48,000-point box's fillets 0.139 -> 0.134, the blade's sides -1.2 % instead of -0.3 %),
#: but the table scan took 1.10 to 1.15 times as long; with every such estimate, also those
#: kept over 48 and 96, the blade's sides -4.9 %, the 20,000-point blade in 1.5 times the
#: time (docs/accuracy.md section 9, step 32).
CYLINDER_SHARE = 2
#: Whether cylinder fits may replace estimates where no sphere does (added at stop 53;
#: docs/accuracy.md section 9, step 31).
CYLINDERS = True


def candidates(res, rows: np.ndarray, largest: int) -> np.ndarray:
    """The rows a sphere fit may replace, shape (c,), int64: estimated, over at most
    :data:`TRIED_SHARE` times ``largest`` neighbors."""
    ok = (res.status[rows] == Status.OK) & (res.neighbor_count[rows] <= TRIED_SHARE * largest)
    return rows[ok]


def umbilic_pass(points, query_nearest, res, rows, noise: float, largest: int,
                 outliers: np.ndarray, chunk: int, reach=None, floor_scale=0.0, grow=None,
                 tick=None, cylinders=None, own_std=None):
    """Replace the estimates of ``rows`` where a sphere or cylinder fit reads them better, in
    place.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    query_nearest : callable
        ``query_nearest(idx, k)`` -> (nbr (m, k) int, d2 (m, k)): the k nearest points of
        ``points[idx]``, nearest first.
    res : CurvatureResult
        The estimates so far (k1, k2, their standard errors, normals, principal directions,
        neighbor counts).
    rows : ndarray, shape (r,), int64
        The points whose estimates are wanted.
    noise : float
        The cloud's noise (length unit); nothing is done where it is not finite.
    largest : int
        Most neighbors a fit may use (a user's ``k`` holds here too).
    outliers : ndarray, shape (n,), bool
        Points left out of every fit.
    chunk : int
        Query points per batch.
    reach : ndarray, shape (n,), optional
        Each point's reach, raised in place to the distance of its farthest list neighbor.
    floor_scale : float
        1 / spacing: the rounding floor of the standard errors (:func:`with_floor`).
    grow, tick : callable, optional
        Progress: ``grow(m)`` announces the m points to be fitted, ``tick(m)`` reports m done.
    cylinders : ndarray, shape (n,), bool, optional
        Where cylinder fits may be tried (everywhere by default, nowhere where
        :data:`CYLINDERS` is false).
    own_std : ndarray, shape (n,), bool, optional
        Set where a fit replaced the estimate: its standard errors are its own
        (:data:`~curvature.uncertainty.OWN_STD_SCALE`), not to be widened by the neighbor
        spread.

    Returns
    -------
    int
        How many estimates were replaced.
    """
    n = points.shape[0]
    sizes = np.array([s for s in SIZES if s <= min(largest, n)], np.int64)
    if not np.isfinite(noise) or noise <= 0.0 or sizes.size == 0:
        return 0
    query_rows = candidates(res, rows, int(sizes[-1]))
    if grow is not None:
        grow(query_rows.shape[0])
    # The estimates kept over at most SHORT_SHARE times the last short size are tried over
    # the short ladder (a shorter list), only the wider ones over every size: a 384-point
    # sphere costs a 384-neighbor query (docs/accuracy.md, section 9, step 28).
    short = sizes[:SHORT_SIZES]
    if cylinders is None or not CYLINDERS:
        cylinders = np.full(n, CYLINDERS)
    wide = _wide(res, query_rows, int(short[-1]), cylinders)
    replaced = 0
    for group, ladder in ((query_rows[~wide], short), (query_rows[wide], sizes)):
        fcrit = (f_critical(ladder), f_critical(ladder, extras=CYLINDER_EXTRAS))
        for start in range(0, group.shape[0], chunk):
            query = group[start:start + chunk]
            out = _fits(points, query_nearest, res, query, noise, ladder, fcrit, outliers,
                        reach, cylinders)
            ok = np.isfinite(out[0])
            _store(res, query[ok], *(x[ok] for x in out), floor_scale)
            if own_std is not None:
                own_std[query[ok]] = True
            replaced += int(ok.sum())
            if tick is not None:
                tick(query.shape[0])
    return replaced


def _wide(res, rows, short_last: int, cylinders) -> np.ndarray:
    """Which of ``rows`` (shape (r,)) are tried over every size, shape (r,), bool: the
    estimates kept over more than :data:`SHORT_SHARE` times ``short_last`` neighbors, and
    those kept over at least :data:`CYLINDER_SHARE` times it that a cylinder may replace."""
    count = res.neighbor_count[rows]
    flat_axis = reads_axis_flat(res.k1[rows], res.k2[rows], res.k1_std[rows], res.k2_std[rows])
    return (count > SHORT_SHARE * short_last) | (
        (count >= CYLINDER_SHARE * short_last) & cylinders[rows] & flat_axis)


def _store(res, at, k, se, count, kind, floor_scale) -> None:
    """Write the fits that replace the estimates at ``at`` (shape (r,); the other arrays as
    :func:`_fits` returns them there) into ``res``: a sphere's k as k1 and k2, a cylinder's
    across its axis and 0 along it, ordered k1 >= k2 (the estimate's directions stay,
    swapped where the order asks it, (d1, d2) -> (d2, -d1) to keep their handedness); the
    fit's standard error times :data:`~curvature.uncertainty.OWN_STD_SCALE` for both."""
    cylinder = kind > 0
    k1 = np.where(cylinder, np.maximum(k, 0.0), k)
    k2 = np.where(cylinder, np.minimum(k, 0.0), k)
    swap = cylinder & ((kind == 2) == (k >= 0.0))
    d1, d2 = res.dir1[at], res.dir2[at]
    res.dir1[at] = np.where(swap[:, None], d2, d1)
    res.dir2[at] = np.where(swap[:, None], -d1, d2)
    std = with_floor(OWN_STD_SCALE * se, k1, k2, floor_scale)
    res.k1[at], res.k2[at] = k1, k2
    res.k1_std[at] = std
    res.k2_std[at] = std
    # H = k / 2 on a cylinder
    res.mean_std[at] = np.where(cylinder, 0.5 * std, std)
    res.neighbor_count[at] = count


def _fits(points, query_nearest, res, query, noise, sizes, fcrit, outliers, reach, cylinders):
    """:func:`~curvature.fitting.umbilic.umbilic_fits` at ``query`` over the ladder
    ``sizes`` (``fcrit``: its :func:`~curvature.fitting.umbilic.f_critical` for the sphere
    and the cylinder; ``cylinders`` (n,): where cylinders may be tried): the fit's
    curvature, standard error, size and kind per point, shapes (m,), NaN (0) where the
    estimate stays."""
    nbr, d2 = query_nearest(query, int(sizes[-1]))
    nbr = np.where(outliers[nbr], -1, nbr)
    m = query.shape[0]
    out_k, out_se = np.empty(m), np.empty(m)
    out_count, out_kind = np.empty(m, np.int64), np.empty(m, np.int64)
    umbilic_fits(points, res.normals, res.dir1, res.dir2, query, nbr, noise, sizes, *fcrit,
                 res.k1[query], res.k2[query], res.k1_std[query], res.k2_std[query],
                 res.neighbor_count[query].astype(np.int64), cylinders[query], out_k, out_se,
                 out_count, out_kind)
    if reach is not None:
        reach[query] = np.fmax(reach[query], np.sqrt(d2[:, -1]))
    return out_k, out_se, out_count, out_kind
