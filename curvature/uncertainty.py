"""Per-point standard errors of k1, k2 and H, and the flag of untrustworthy estimates.

Where the standard errors come from (each from the fit that produced the value):

- neighborhood methods (``knn``, ``tc``, ``egg``, ``mesh``, any fit): the least-squares
  covariance of the local quadratic over the neighborhood the fit used, from its residual and
  the positions of its points, propagated to k1, k2 and H
  (:func:`curvature.fitting.uncertainty.design_std`), times a factor per fit model
  (:data:`FIT_CALIBRATION`);
- the default's noisy branch (:func:`anchored_std`): the calibrated standard error of the fit
  its scale selection kept (``sigma_s`` of :mod:`curvature.fitting.scale_selection`),
  combined with the bias of its k1 (k2) that the smaller fits show (a precision-weighted
  estimate from their disagreements, :data:`BIAS_WEIGHT`) and the bias its residual shows
  beyond the cloud's noise (:data:`MODEL_BIAS`), except where the fit spans both faces of a
  wall with parallel faces, whose residual is the wall's half thickness
  (:mod:`curvature.fitting.parallel_sheets`, :data:`SHEETS_SIGMA_POWER`);
- the default's clean branch (implicit quadrics, exact on quadrics): the model error its
  residual implies, ``CLEAN_CALIBRATION * residual / h^2``; zero residual, zero error;
- the default, both branches, then: widened by how far the point's nearest neighbors'
  curvatures lie from its own (:data:`NEIGHBOR_SPREAD_WEIGHT`): a point read from an
  anchor's fit a cell away, or where the curvature changes fast (a fillet's edge, an
  ellipsoid's tip), errs by more than the fit's own error, and there its neighbors, read
  from other fits or at other places, disagree;
- except the sphere and cylinder fits of the default's last pass
  (:mod:`curvature.fitting.umbilic`): their least-squares standard error times
  :data:`OWN_STD_SCALE`, which the neighbor spread leaves as it is; and the tips of thin
  wedges (:mod:`curvature.fitting.wedge_tip`): the standard error of k across the edge from
  the fit of its radius and of the faces' apex, which the spread leaves too.

A floor of :data:`STD_FLOOR` of the curvature itself stands for the discretisation error no
residual shows (sampling, foot point).
"""

from __future__ import annotations

import numpy as np

__all__ = ["ANCHORED_MEAN_SHARE", "BIAS_WEIGHT", "CLEAN_CALIBRATION", "FIT_CALIBRATION",
           "MODEL_BIAS", "NEIGHBOR_SPREAD_WEIGHT", "NOISE_RESIDUAL_SHARE", "OWN_STD_SCALE",
           "REFINED_AGAIN_SIGMA", "SHEETS_SIGMA_POWER", "STD_FLOOR", "THIN_NEIGHBORS",
           "UNCERTAIN_SHARE", "anchored_std", "uncertain", "with_floor"]

#: Power of noise / distance that scales the sigma of a fit over two parallel sheets
#: (:func:`anchored_std`). With 1 (sigma as if the noise alone were its residual) the
#: 20,000-point thin plate (faces 4 spacings apart) covered 0.93 to 0.99 with 2 standard
#: errors, but the 10,000-point one (3 spacings) 0.67 to 0.92: there the fits over both faces
#: err by more than their noise. With 0.5: 0.97 to 1.00 and 0.77 to 0.96 (docs/accuracy.md,
#: section 10, stop 48).
SHEETS_SIGMA_POWER = 0.5
#: Factor of the height-function covariance per fit model (benchmarks/uncertainty.py).
FIT_CALIBRATION = {"monge": 1.0, "adaptive": 1.0, "implicit": 1.0, "nfr": 1.0}
#: Curvature error per unit of residual / h^2 of a noise-free implicit quadric fit.
CLEAN_CALIBRATION = 7.0
#: Standard error of H per unit of the larger of the anchored fits' errors of k1 and k2.
ANCHORED_MEAN_SHARE = 0.8
#: Weight of the bias of k1 (k2) the default's smaller fits show (``bias`` of
#: :func:`curvature.fitting.scale_selection.multiscale_anchor_fits`, a precision-weighted
#: estimate). Its most precise witnesses are the normal fits below the kept one, which fit
#: the same normals and so agree with it more closely than their sigmas say: the mean reads
#: low. Calibrated by benchmarks/uncertainty.py with :data:`MODEL_BIAS` and
#: :data:`NEIGHBOR_SPREAD_WEIGHT` (docs/accuracy.md section 10, stop 40: a grid over the
#: three on seeds 1 and 2; 0.5 to 3 here). Until stop 39 each curvature also counted half of
#: the other's bias; without it the grid's best was no worse.
BIAS_WEIGHT = 3.0
#: Curvature error per unit of ``sqrt(d^2 - noise^2) / h^2`` of a default's fit whose RMS
#: distance d to its surface exceeds the cloud's noise (h the RMS distance of its points from
#: the anchor): the shape it does not follow, which no smaller fit shows where they all share
#: it (the stage-1 normals' smoothing at a fillet's edge). The cloud's noise is the plan's
#: cubic-fit residual over :data:`NOISE_RESIDUAL_SHARE`.
MODEL_BIAS = 1.0
#: RMS residual of a cubic height fit (10 terms) over 25 points, per unit of noise:
#: sqrt(1 - 10 / 25).
NOISE_RESIDUAL_SHARE = 0.77
#: The default's calibrated sigma of a second-pass fit (section 8's ``sigma_s``) reads the
#: RMS distance of the fit's points to its surface, which refining the normals it fits a
#: second time (AutoRun._refine_again) leaves as it was, while their errors fall: this share
#: of it counts where the anchor's normals were refined again (measured below).
REFINED_AGAIN_SIGMA = 0.85
#: The default's standard errors grow to ``hypot(std, NEIGHBOR_SPREAD_WEIGHT * spread)``,
#: with ``spread`` the RMS difference of k1 (k2, H) between a point and its 7 nearest
#: neighbors (:func:`curvature.fitting.uncertainty.add_neighbor_spread`). Calibrated by
#: benchmarks/uncertainty.py (72 noisy cells of 9 shapes, 0.05 to 0.5 % noise, both noise
#: models): share of cells with the k1 and k2 coverage of 2 standard errors within 90-98 %
#: 24 % without it, 39 % with 1.5 and 1.75; share covering at least 90 % 29 %, 74 % and 82 %;
#: Spearman >= 0.5 6 %, 12.5 % and 12.5 %. The 96-point circular rung (stop 36) widened the
#: fits' own standard errors where it shows a bias: with 1.75 32 % in band and 88 % covering
#: 90 %, with 1.25 / 1.4 / 1.5 / 1.6 39 / 40 / 40 / 39 % in band and 75 / 81 / 82 / 85 %
#: covering 90 %; 1.6 now. The spread counts the neighbors' noise too (a
#: neighbor read from another anchor's fit differs by about sqrt 2 standard errors where the
#: fits are unbiased); counting only the spread beyond both points' standard errors gave 35 %
#: in band but 44-46 % covering at least 90 % (weights 1.5 and 2.5): the noise-calibrated
#: standard errors alone under-cover. A spread beyond a linear trend of the neighbors'
#: curvatures did worse still (18-36 % in band): where the curvature changes fast is where the
#: fits err (the ellipsoid's k1 covered 0.58-0.79 that way, 0.96-0.99 with the plain spread).
#: On the real scan bun000 the median standard error of k1 rises from 16 to 42 inside and
#: from 30 to 52 at the range image's edges, and the share of points flagged uncertain from
#: 25 to 66 % (docs/accuracy.md section 10). Stop 40 searched it again with
#: :data:`BIAS_WEIGHT` and :data:`MODEL_BIAS` (0.6 to 1.6): 1.6 stays.
NEIGHBOR_SPREAD_WEIGHT = 1.6
#: The sphere and cylinder fits of the default's last pass (curvature.fitting.umbilic) report
#: their least-squares standard error times this, and the neighbor spread does not widen it:
#: their one curvature term passed an F test against a wider model, their residual matched
#: the noise and Lepski's rule held over their sizes, so they show no bias the spread would
#: have to stand for; what the spread read there was the bias of the estimates beside them
#: (the 96,000-point filleted box at 0.05 % noise: the fillets' cylinders err 0.029, median,
#: their least-squares standard error is 0.038 and the widened one was 0.20, whose 2 covered
#: 0.9998 of their errors; 2 of this one cover 0.97). The factor covers the pick of the size
#: with the smallest standard error; even so the 12,000-point box's 48- to 96-point
#: cylinders at 0.25 % noise cover 0.60. benchmarks/uncertainty.py (seed 1, 72 noisy cells,
#: CYLINDER_SHARE 1 of curvature.estimators.umbilic_pass), share in band / covering at least
#: 90 %: with the spread 24 / 79 %; without it, factor 1 43 / 76 %, 1.25 39 / 79 %, 1.5 32 /
#: 79 %, 2 26 / 79 % (docs/accuracy.md section 10, stop 54).
OWN_STD_SCALE = 1.25
#: Relative floor of a standard error (share of max(|k1|, |k2|)).
STD_FLOOR = 1e-9
#: A point is uncertain when a standard error of k1 or k2 exceeds this share of its
#: curvature: then the 2-sigma interval of a curvature reaches past zero.
UNCERTAIN_SHARE = 0.5
#: ... or when its fit used fewer neighbors than this.
THIN_NEIGHBORS = 10


def with_floor(std: np.ndarray, k1: np.ndarray, k2: np.ndarray,
               scale: float = 0.0) -> np.ndarray:
    """``sqrt(std^2 + (STD_FLOOR max(|k1|, |k2|, scale))^2)``, shape (n,).

    ``scale`` (1 / length, e.g. 1 / point spacing) keeps the floor above rounding on flat
    faces, where the curvature itself is zero.
    """
    floor = STD_FLOOR * np.maximum(np.maximum(np.abs(k1), np.abs(k2)), scale)
    return np.hypot(std, floor)


def anchored_std(sigma: np.ndarray, bias: np.ndarray, distance: np.ndarray, h: np.ndarray,
                 noise: float, sheets: np.ndarray | None = None) -> np.ndarray:
    """Standard errors of k1 and k2 of the default's anchored fits, shape (a, 2).

    ``hypot(sigma, BIAS_WEIGHT * bias, MODEL_BIAS * sqrt(max(distance^2 - noise^2, 0)) / h^2)``
    (module docstring); no model term where ``noise`` is not finite (clean clouds). A fit over
    both faces of a wall with parallel faces (``sheets``) has the wall's half thickness for
    its distance, which is no misfit: there the distance counts as the noise (no model term)
    and sigma, which grows with it, shrinks by the square root of their ratio
    (:data:`SHEETS_SIGMA_POWER`; :mod:`curvature.fitting.parallel_sheets`).

    Parameters
    ----------
    sigma : ndarray, shape (a,)
        Calibrated standard error of each kept fit (inf where none was usable).
    bias : ndarray, shape (a, 2)
        The bias of its k1 and k2 the smaller fits show.
    distance, h : ndarray, shape (a,)
        The kept fit's RMS distance of its points to its surface and from its anchor.
    noise : float
        The cloud's noise (length unit).
    sheets : ndarray, shape (a,), bool, optional
        The fits over two parallel sheets.
    """
    if sheets is not None and np.isfinite(noise) and sheets.any():
        with np.errstate(invalid="ignore", divide="ignore"):
            share = np.where(sheets & (distance > noise),
                             (noise / distance) ** SHEETS_SIGMA_POWER, 1.0)
        sigma = sigma * share
        distance = np.where(sheets, np.minimum(distance, noise), distance)
    model = np.zeros_like(sigma)
    if np.isfinite(noise):
        with np.errstate(invalid="ignore", divide="ignore"):
            model = MODEL_BIAS * np.sqrt(np.maximum(distance * distance - noise * noise, 0.0))
            model = np.where(np.isfinite(model) & (h > 0.0), model / (h * h), 0.0)
    return np.hypot(sigma[:, None], np.hypot(BIAS_WEIGHT * bias, model[:, None]))


def uncertain(k1, k2, k1_std, k2_std, neighbor_count, status, diagonal: float) -> np.ndarray:
    """The flag of estimates not to be trusted, shape (n,), uint8 (1: uncertain).

    A point is uncertain when it has no estimate (``status != 0``), when its fit used fewer
    than :data:`THIN_NEIGHBORS` neighbors, or when the standard error of k1 or of k2 exceeds
    :data:`UNCERTAIN_SHARE` times ``max(|k1|, |k2|, 1 / diagonal)``: the curvature is not
    known to within half its size. The term ``1 / diagonal`` (a sphere as large as the
    cloud's bounding-box diagonal, which the cloud cannot tell from a plane) keeps flat faces
    with small errors trusted.

    Parameters
    ----------
    k1, k2, k1_std, k2_std : ndarray, shape (n,)
    neighbor_count, status : ndarray, shape (n,), int
    diagonal : float
        Bounding-box diagonal of the cloud (length unit).

    Returns
    -------
    ndarray, shape (n,), uint8
    """
    floor = 1.0 / diagonal if diagonal > 0.0 else 0.0
    scale = np.maximum(np.maximum(np.abs(k1), np.abs(k2)), floor)
    with np.errstate(invalid="ignore"):
        loose = ~(np.maximum(k1_std, k2_std) <= UNCERTAIN_SHARE * scale)
    bad = (np.asarray(status) != 0) | (np.asarray(neighbor_count) < THIN_NEIGHBORS) | loose
    return bad.astype(np.uint8)
