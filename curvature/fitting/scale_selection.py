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
* where the circular 48-point rung finds one principal curvature well below the other (a
  fillet, a leading edge), a ridge rung fits 96 points of a patch stretched along the smaller
  curvature's direction: as narrow across the ridge as the 24-point rung, with four times its
  points; a short ridge rung takes its 96 points from the 192 nearest only, so it is shorter
  and wider; beside the tightest ridges a long one fits 192 points from the 1,536 nearest
  (:data:`RIDGE_LONG_TURN`), as narrow as the ridge rung and twice as long. Their patches and
  the circular rungs' are not nested (a ridge rung is narrower and longer than the 48-point
  rung), so each judges only what its patch cannot bias more than the other's
  (:func:`_witnesses`): a wider rung the ridge rung's curvature along the ridge, the ridge
  rung the short one's across it; beside a tight, nearly cylindrical ridge or a tight cap
  the normal fits, whose stage-1 normals are smoothed there, are not used
  (:data:`RIDGE_TURN`);
* the largest fit is kept whose k1 and k2 agree with those of every smaller fit within ``gamma
  (sigma_s + sigma_r)`` (Lepski's rule: its bias is not visible above the noise of any smaller fit;
  the 24-point fit only checks the 48-point one, and a normal quadric that misfits its
  normals more than a top's polynomial normal field does not check that top,
  :func:`_witnesses`), and whose sigma is at most :data:`SIGMA_GROWTH`
  times the smallest below it: a fit that reached across a thin wall or over an edge has a large
  residual distance, and so a large sigma, even while its wide interval still overlaps the others
  (a top's distance there is to a sphere or cylinder of its curvature, not to a paraboloid);
* a smaller Monge rung that the kept fit disagrees with by clearly more than their errors, and
  whose expected error is below the kept fit's as that disagreement shows it, replaces it
  (:func:`_least_error`).

The kept model is written in the same arrays as ``nfr_anchor_fits`` so that
:func:`~curvature.fitting.normal_field.nfr_from_anchors` reads it unchanged.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .kernels import MAX_FOOT_DIST, fit_monge, gather_local, principal_axes, spans_surface
from .linalg import cholesky, solve_lower
from .normal_field import MODEL_FIELD, nfr_anchor_fits_one, supported
from .normal_quadric import N_QUAD, curvature_from_quadric, regress_normal_quadric
from .quadric import DEGENERATE, OK, foot_point, gradient_at, sampson_rms, shape_operator

__all__ = ["BORDER_SIDE", "DEFAULT_GAMMA", "DESIGN_ISOTROPIC", "KIND_MONGE", "KIND_MONGE_RIDGE",
           "KIND_NORMAL_QUADRIC", "RUNGS", "RUNG_GROWTH", "SIGMA_FLOOR", "TOPS", "TURN_GUARD",
           "TURN_MONGE_K", "TURN_SLACK", "design_spread", "ladder_estimates",
           "multiscale_anchor_fits", "one_sided", "pass_rungs", "scale_sigma", "turn_supports"]

#: Rung models: a positional Monge quadric, the normal-constrained quadric, or a Monge
#: quadric with CIRCULAR_ROUNDS of the circular correction (kernels.fit_monge). On a filleted
#: box at 0.05 % noise the correction cut the 48-point rung's mean |k1| / |k2| error at the
#: corners from 0.53 / 0.24 to 0.14 / 0.22, and on a blade's leading edge (k = 20, 0.1 %)
#: from 3.8 to 0.9; on planes its calibration is within 5 % of the plain fit's.
KIND_MONGE = 0
KIND_NORMAL_QUADRIC = 1
KIND_MONGE_CIRCULAR = 2
CIRCULAR_ROUNDS = 3
#: A circular Monge quadric over a patch stretched along a ridge: the points of the nearest
#: RIDGE_POOL nearest to the anchor when distances along the smaller principal curvature's
#: direction (of the last circular rung) count 1 / RIDGE_ASPECT. Across a fillet or a
#: leading edge it is as narrow as the isotropic rung of a quarter of its points, so no more
#: biased where the curvature ends at the ridge's sides, with four times the points. Its
#: quadric is held in units of that width, and its support (|k| h <= SUPPORT) judged by it: a
#: patch's length along a straight ridge bounds no curvature. At aspect 2 (stop 31 to 36; as
#: narrow as the 48-point rung) the rung read a leading edge of 2.6 spacings' radius (the
#: bench's blade, 10,000 points, k = 20, 0.1 % noise) 18.2 like the 48-point rung, whose
#: patch wraps about 85 degrees each way and onto the flat sides; at aspect 4 20.4, mean of
#: the larger of the k1 and k2 errors 0.81 (24-point rung: 20.4 and 1.83, its noise). Its
#: calibration (RUNGS) stays 4.1: at aspect 4 benchmarks/calibrate_scales.py measures 2.9 to
#: 4.1, and 3.5 cost the sphere and the Bezier patch up to 5 % for 2 to 4 % on the fillets.
KIND_MONGE_RIDGE = 3
RIDGE_ASPECT = 4.0
#: A ridge rung is fitted only where the last circular rung's smaller curvature is at most
#: this share of the larger: on a corner sphere its direction is arbitrary and a stretched
#: patch reaches into the fillets (a filleted box's corners: 0.45 -> 0.89 without the test).
RIDGE_RATIO = 0.5
RIDGE_POOL = 384
#: The short ridge rung: the ridge rung's 96 points from the nearest RIDGE_SHORT_POOL only,
#: the ridge rung of the refits (``AutoRun._refit``, 192 neighbors) until stop 42. The ball
#: of 192 cuts its ellipse along the ridge: about 0.8 times as wide across as the 48-point
#: rung and as long as that ball. Beside a leading edge of 2.6 spacings' radius (the bench's
#: 10,000-point blade, 0.1 % noise) it reads the edge low like the 48-point rung (mean of
#: the larger of the k1 and k2 errors at the refitted points 1.2, the ridge rung 0.6); on a
#: fillet of 6 spacings (the filleted box at 0.05 %) its standard error is half the ridge
#: rung's, and it turns down the normal-quadric rungs that read the fillet 8 % low, which
#: the ridge rung's wider interval lets pass (the box's fillets +18 % without it).
KIND_MONGE_RIDGE_SHORT = 4
RIDGE_SHORT_POOL = 192
#: The long ridge rung: 192 points at aspect RIDGE_LONG_ASPECT from the nearest
#: RIDGE_LONG_POOL (whose ball cuts the patch to about twice the ridge rung's length at 0.9 of
#: its width), fitted only beside a significant, nearly cylindrical ridge whose framing rung
#: turns its normal by more than RIDGE_LONG_TURN over its patch (``|k| h``; the bench blade's
#: leading edge 0.94 to 1.17, the filleted box's fillets 0.40 to 0.53, where it reached the
#: corners along the fillets: fillets +10 % at 0.05 % noise without the test). Beside the
#: bench blade's leading edge (radius 2.6 spacings, 0.1 % noise) it halves the ridge rung's
#: noise where every shorter patch's is the error: mean of the larger of the k1 and k2
#: errors 0.66 -> 0.42 (seeds 1 and 2). Lists are that long only where an anchor asks for it
#: (``longer`` of :func:`multiscale_anchor_fits`). Calibration 3.3: measured 3.29 on a
#: 20,000-point cylinder and 3.18 on a sphere at 0.1 % noise (the ridge rung's 3.85, 3.80).
KIND_MONGE_RIDGE_LONG = 5
RIDGE_LONG_POOL = 1536
RIDGE_LONG_ASPECT = 16.0
RIDGE_LONG_TURN = 0.7
#: How a smaller fit judges a larger one in Lepski's rule (``witness`` of :func:`_witnesses`):
#: not at all (0), by k1 and k2 (1), by the curvature smaller in magnitude only (ALONG: a
#: circular rung wider across a ridge than the ridge rung, whose curvature across it the
#: wider patch reads low), or by the larger only, within NESTED_AGREEMENT combined standard
#: errors (ACROSS: the ridge rung judging the short one, which shares most of its points and
#: is shorter along the ridge, where the longer patch is the one that may reach a corner).
ALONG = 2
ACROSS = 3
#: A ridge rung's sigma may exceed that of a wider circular rung below it by this factor in
#: the growth test (it fits a narrower patch: beside the bench blade's leading edge its
#: sigma is 0.7 to 1.15 times the 48-point rung's; on the filleted box's fillets, where its
#: patch reaches a corner along the fillet, 1.7 to 3.5 times).
RIDGE_GROWTH = 1.3
#: The same for the long ridge rung against every fit below it (all wider across the ridge):
#: by its formula its sigma is 2.4 to 3.7 times the 96-point ridge rungs' and 1.1 to 1.5 times
#: the 24-point rung's beside the bench blade's leading edge, where its error is the least
#: (with the 24-point rung a peer, 29 of the edge's 143 points kept a 96-point rung: 0.471
#: instead of 0.434). 6 leaves room above the largest ratio measured; at 3 (with the
#: ridge rungs' calibration, 4.1) the edge read 0.453 over seeds 1 and 2, 0.418 now.
RIDGE_LONG_GROWTH = 6.0
#: ... where the ridge is real: the widest circular rung below the ridge rung reads its larger
#: curvature above this many of its standard errors (the bench blade's leading edge 15 to 20,
#: the filleted box's fillets about 40). On a noisy plane a 48-point rung frames a ridge by
#: chance: there the usual rules hold, or the ridge rung's chance readings are kept (a
#: 10,000-point plane at 0.1 % noise: p99.9 of |k| 0.08-0.15 -> 1.4-1.5 on two seeds of 4).
RIDGE_SIGNIFICANCE = 4.0
#: Beside a significant ridge that is nearly a cylinder (the ridge rung's smaller curvature
#: below RIDGE_CYLINDRICAL times its larger) and tight (the circular rung that framed it turns
#: its normal by more than RIDGE_TURN radians over its patch's RMS radius, ``|k| h``), the
#: normal fits (the normal-quadric rungs and the tops) are not used: their normals come from
#: PCA over 48 neighbors, smoothed where the ridge meets its flanks, and they read such a ridge
#: low with small standard errors (the filleted box's fillets, ``|k| h`` 0.40 to 0.53: the
#: 96-point normal quadric 8 % low with a sigma of 0.03; the blade's leading edge, 0.94 to
#: 1.17). Smooth shapes stay below (issue 23's 10,000-point clouds, p99: torus 0.30, cylinder
#: 0.17, sphere 0.12, Bezier patch 0.07), but an ellipsoid's ends reach 0.64 (p95 0.43) with a
#: smaller curvature 0.12 to 0.30 times the larger: without the cylinder test its mean error at
#: 0.1 % rose 20 %, at RIDGE_TURN 0.2 the torus's 110 to 180 %. The same holds beside a
#: tight cap (:func:`_tight_cap`: both curvatures of the framing rung within RIDGE_RATIO of
#: each other, a filleted box's corners, |k| h about 0.46): there the 96-point normal quadric
#: read 4.1 to 4.2 for 5 with a sigma of 0.06 and passed (the box's corners at 0.1 % noise,
#: seeds 1 to 4: 0.556 / 0.529 / 0.558 / 0.491 -> 0.510 / 0.510 / 0.474 / 0.430).
RIDGE_CYLINDRICAL = 0.1
RIDGE_TURN = 0.4
#: A Monge rung whose residual exceeds this share of its patch's RMS radius (across the ridge
#: for a ridge rung) is not used. Noise that large against the patch biases a height fit
#: instead of only scattering it: on a 1M-point torus at 0.1 % noise (residual 0.26 of the
#: 48-point patch's radius) the 48-point and ridge rungs read about 25 for a true 1 with
#: standard errors near 6, and turned the wider fits down. Elsewhere the ratio is about 0.05
#: (10,000-point clouds at 0.5 %, parts at 0.1 %).
MONGE_NOISE_LIMIT = 0.12
#: The rungs of each pass, ``(neighbors, model, calibration)``: prefix fits tried below the
#: tops. The calibration is the standard error per unit of d / (h^2 sqrt(s)): RMS curvature
#: error over that RMS measured on noisy planes, spheres and cylinders (0.1 to 0.5 % noise,
#: 20,000 points; benchmarks/calibrate_scales.py), constant within about 15 % across shapes
#: and noise; the Monge rungs' errors are larger than their residuals say because the fit sees
#: few points per unknown. Pass 1 ("refine") only refines normals: Monge rungs would tilt them
#: by their noisy curvature over a cell's width. The 96-point circular rung (calibration 4.4
#: to 5.5) keeps a positional fit in the ladder where a denser cloud makes the 48-point patch
#: too small for its noise to show the normal fits' bias at corners and fillets: on a
#: 24,000-point filleted box at 0.05 % noise the 48-point rung's standard error at a corner
#: was 0.5 against 0.06 at 12,000 points, and the biased 192-point normal fits passed
#: (corners 0.28 at 12,000 points, 0.75 at 24,000; with the rung 0.35 and 0.46).
RUNGS = {
    "refine": ((96, KIND_NORMAL_QUADRIC, 1.9), (192, KIND_NORMAL_QUADRIC, 2.6)),
    "fit": ((24, KIND_MONGE_CIRCULAR, 6.7), (48, KIND_MONGE_CIRCULAR, 5.5),
            (96, KIND_MONGE_RIDGE, 4.1), (96, KIND_MONGE_RIDGE_SHORT, 4.1),
            (192, KIND_MONGE_RIDGE_LONG, 3.3), (96, KIND_MONGE_CIRCULAR, 5.0),
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
#: A default top is kept below ``k`` only when it is at most this fraction of ``k`` (2 / 3
#: until stop 40; 0.75 keeps the 768 top below a 1152 one).
TOP_GAP = 0.75
#: Tops wider than this many neighbors are the ones the ``side_limit`` of
#: :func:`multiscale_anchor_fits` may turn down.
SIDE_FROM = 768
#: Agreement tolerance in standard errors. 5 (before the circular rungs) let the wider
#: normal fits' bias at corners and fillets pass (filleted box at 0.05 %: corners 1.02 with
#: the circular rungs, 0.45 with 3.5, mean of the larger of the k1 and k2 errors); 3.5 costs
#: about 10 % on noisy smooth shapes (10,000-point sphere at 0.5 %: 0.0142 -> 0.0156), 3
#: already 40 %.
DEFAULT_GAMMA = 3.5
#: Agreement a wider top needs with the top below it, in combined standard errors.
TOP_AGREEMENT = 1.5
#: A fit whose sigma exceeds the smallest sigma below it by more than this is turned down.
#: A top's sigma in this test is that of its distance to the biconic of its own curvature
#: (:func:`~curvature.fitting.normal_field.regress_normals`) where it kept the normal field,
#: not to the paraboloid: a 384-point patch of a torus (10,000 points) wraps 0.7 of the
#: tube's radius each way, and the paraboloid missed its points by 0.026 against 0.001 to
#: 0.008 for the 24-point rungs, which turned the tops down on most of the tube at 0.1 to 0.3
#: % noise (at 0.1 % view noise 57 % of its points kept 192-point fits or less; mean of the
#: k1 and k2 errors 0.0174 -> 0.0134). On a box's face beside a fillet the tops' patches
#: bend onto the fillet, and both distances stay far above the noise.
SIGMA_GROWTH = 2.0
#: The growth limit of a ladder rung (below the tops): a rung's sigma may not exceed the
#: smallest below it at all. Each rung holds twice the points of the one below, or fits the
#: normals, whose sigma is several times smaller (expected ratios 0.1 to 0.3), so a rung as
#: noisy as a smaller one shows a misfit (an edge, a fillet's end) that its interval hides.
#: 10,000-point clouds, seeds 1 to 4, against 2 for every fit: the stepped cylinder's
#: shoulder -22 to -26 %, the filleted box's fillets -2 to -9 %, its faces -1 to -5 %, its
#: corners with view noise -5 to -15 %, the torus at 0.1 % view noise -9 %, the smooth shapes
#: otherwise within 0.5 %. 0.8 (faces -4 % more, but the box's corners at 0.1 % +7 %) and
#: 0.5 (corners -16 %, but the leading edge +11 % and the cylinder at 0.1 % view +5 %) move
#: further both ways.
RUNG_GROWTH = 1.0
#: A fit's curvature farther than this many combined standard errors from a smaller fit's
#: shows a bias of that fit: the excess is its estimate where :func:`_least_error` weighs
#: a rung's expected error.
BIAS_SLACK = 1.5
#: Relative floor of sigma (times 1 / h): noise-free fits are exact only up to rounding.
SIGMA_FLOOR = 1e-7
#: Combined standard errors, as a share of ``gamma``, by which a kept fit must disagree with
#: a smaller Monge rung before that rung may replace it (:func:`_least_error`). A false switch
#: costs the ratio of the two sigmas, so it must be rare on smooth shapes. At gamma 3.5: with
#: 2.5 a 10,000-point Bezier patch at 0.5 % noise erred 0.046 (0.039 without switching), with
#: 3 0.042; the filleted box's fillets at 0.05 %: 0.205, 0.238 with 3, 0.273 with 3.5. A share
#: of gamma so that the dense share's wider gamma (DENSE_GAMMA_SCALE in
#: curvature.estimators.auto) widens it too. The 24-point rung never replaces a fit (as in
#: Lepski's rule, it is too noisy to judge the others): it took the thin plate's rims
#: (radius 2 spacings, 0.1 %) from 15.7 to 9.9, but its chance readings of 6 to 9.6 on a
#: noisy plane too.
SWITCH_SLACK = 3.0 / 3.5
#: Smallest share of a kept fit's bias its difference with a smaller fit is read as (patches of
#: nearly equal size say little of how the bias grows).
BIAS_SHARE_MIN = 0.25
# A foot point farther than this many fit units from the anchor means the fit missed it.
FOOT_LIMIT = 2.0
#: A normal-quadric rung's curvature k over its points' RMS distance h turns the normals by
#: about k h across its patch; the rung is not used where k h exceeds TURN_GUARD times the
#: 90th percentile of its points' normals' angles to the anchor's, plus TURN_SLACK (radians;
#: the noise's own turning on small patches). Over both faces of the blade's wedge (2.6
#: spacings thick, normals 12 degrees apart) 96-point quadrics read k of 26 to 43 on a flat
#: side, k h about 1.4 where the normals turned 0.6 at most (docs/accuracy.md, section 9,
#: step 43); no smooth shape's figure moved.
TURN_GUARD = 2.0
TURN_SLACK = 0.1
#: The same guard on the circular, isotropic and ridge Monge rungs reads PCA normals over
#: this many neighbors (from the anchor's and from their mean, :func:`_turn_agrees`).
#: Against the normals the rungs fit (in the second pass the first pass's, fitted over 96
#: to 384 points) it flattened detail of a few spacings: a sine wave of 10 spacings'
#: wavelength, slope 0.3, erred 10.8 / 10.7 / 10.9 instead of 2.4 / 3.2 / 4.2 noise-free /
#: at 0.05 / 0.1 %. The stage-1 PCA over 48 reads over both faces of a
#: thin wall by its ends and cut: flat points erring above 5 over four grids and three seeds,
#: the blade's 2 -> 2 and the plate's 30 -> 22; over 12, 2 -> 1 and 30 -> 11, the wave as
#: before (docs/accuracy.md, section 9, step 45).
TURN_MONGE_K = 12
#: The calibrated sigma of a Monge rung assumes its points spread around the anchor as in
#: the cloud's interior. A patch cut by the cloud's border (a half-disk) determines the
#: quadratic terms about 3.4 times worse: :func:`design_spread` is sqrt(s) times the largest
#: standard error, per unit of noise, of the Hessian terms of the least-squares height fit in
#: the patch's RMS unit; a uniformly filled disk gives DESIGN_ISOTROPIC (sqrt 18 = 4.24; over
#: random 48-point disks the median is 4.8 and the 99.5th percentile 6.9, over half-disks the
#: median 16). Where a patch lies to one side of its anchor (:data:`BORDER_SIDE`), an isotropic
#: rung's sigma grows by the ratio to DESIGN_SLACK times that. Without it the border points of
#: 10,000-point planes at 0.1 % noise kept 48-point fits that read |k| up to 6 with standard
#: errors of 0.4 to 0.6: at border points (within 1 spacing) the 48-point rung erred a median
#: 2.2 of its standard error, 1.1 inside; with it 1.1 at both (p99 3.5 and 3.1). Inner
#: patches keep theirs (of the 24-point rungs' 1.8 % grow, by at most 1.8).
DESIGN_ISOTROPIC = np.sqrt(18.0)
DESIGN_SLACK = 1.6
#: The same for a ridge rung's patch, stretched RIDGE_ASPECT times along the ridge: median
#: over random 96-point ellipses of that aspect 37.0 (99.5th percentile 52.1; cut along the
#: ridge by a border, 133; at aspect 2: 10.9, 14.6 and 39). Its slack is lower: with
#: DESIGN_SLACK the border's ridge rungs still erred a median 1.54 of their standard errors
#: (p99 6.4) against 1.24 inside; with RIDGE_DESIGN_SLACK 1.24 (p99 5.0), as inside (both
#: measured at aspect 2).
DESIGN_RIDGE = 37.0
#: ... and for the long ridge rung's (192 of 1536 points in a ball, aspect 16): median 217,
#: 99.5th percentile 317, cut along the ridge 866.
DESIGN_RIDGE_LONG = 217.0
RIDGE_DESIGN_SLACK = 1.25
#: Only a patch whose points lie to one side of the anchor (:func:`one_sided` above this; a
#: half-disk's is 0.85, an inner 48-point patch's rarely above 0.45) is taken for one cut by
#: the border. A patch bent around a leading edge also spreads less across it
#: in the tangent plane, which the spread alone counted as a cut too (the bench's leading
#: edge 2.14 -> 2.19). A patch around a thin rim's crest (radius 2 spacings) does lie to
#: one side, its faces behind it, and counts (the plate's rims 17.9 -> 18.4).
BORDER_SIDE = 0.5
#: A normal-quadric rung does not judge a top that kept the polynomial normal field where the
#: rung's mean squared normal misfit exceeds this many times the top's (:func:`_witnesses`).
#: On a torus the quadric misfits any patch of its tube, so the 96- and 192-point quadrics
#: erred a median 2.9 and 5.6 of their standard errors (10,000 points, 0.1 % view
#: noise, refined normals; the 384 and 768 tops 1.2 and 0.7) and turned the tops down where
#: their disagreement passed 3.5 standard errors. On a box's face near a fillet the smaller
#: quadrics fit the face and their misfit is below the top's, so they keep judging. Measured
#: (10,000-point clouds, seeds 1 and 2, mean |error|; docs/accuracy.md section 9, step 10):
#: torus 2 to 16 % less at 0.1 to 0.5 % noise, the blade's sides 23 % less, the filleted
#: box's faces 1 % more; Bezier patch and cylinder 1 to 7 % more. 0.7 and 1.5 gave about the
#: same; leaving every quadric rung out of judging such a top (no misfit test) cost the box's
#: faces 5 to 14 %, and leaving them out of the growth test too spread fillet curvature over
#: them (0.10 -> 0.13 to 0.22).
WITNESS_MISFIT = 1.0
#: Agreement a circular Monge rung needs with the next smaller one (not the 24-point rung), in
#: combined standard errors: the smaller patch is part of the larger, so their noise is shared
#: and gamma's tolerance (made for independent fits) let a 96-point rung that straddled a
#: corner's edge pass against the 48-point one (a 12,000-point filleted box at 0.05 %: corners
#: 0.28 -> 0.49 with the 96-point rung and gamma alone, 0.35 with this at 2).
NESTED_AGREEMENT = 2.0
#: A smaller rung's disagreement with a wider fit counts only where the widest circular rung
#: (of at least CONFIRM_SIZE points: the widest isotropic positional patch) confirms it:
#: where that rung reads no curvature beyond CONFIRM_FLAT of its standard errors and agrees
#: with the wider fit within CONFIRM_AGREEMENT times their summed sigmas, the smaller rung's
#: reading is taken for chance (:func:`_unconfirmed`). Every
#: anchor tests each wide fit against several smaller rungs, so among a cloud's thousands
#: some read 4 of their standard errors by chance: on 10,000-point planes at 0.1 % noise
#: (seeds 1 to 8) a 48-point rung read -2.5 with a sigma of 0.62 and turned every wider fit
#: down, and the 96-point ridge rung, reading the same bump, was kept (-2.9; the 96-point
#: circular rung -0.33, sigma 0.23, the 192-point top 0.00); the largest |k| of those
#: planes was 0.12 to 2.9, 0.07 to 1.1 with this. At a corner, a fillet, a cylinder's side the
#: widest circular rung reads the curvature itself, beyond CONFIRM_FLAT of its sigma, and
#: the smaller rungs judge as before. Without that flatness test (the wide rung's agreement
#: alone) the filleted box's corners erred 17 % more and its faces 4 %: the wide rung's
#: interval let their biased wider fits pass; at CONFIRM_FLAT 2 one plane of the four kept
#: a 1.6 (its wide rung read 2.6 of its sigmas).
CONFIRM_SIZE = 96
CONFIRM_FLAT = 3.0
CONFIRM_AGREEMENT = 2.0


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
    # A ridge rung's patch is not a prefix of the list: the long one is tried wherever the
    # 96-point ones are.
    ridge = min((r[0] for r in rungs if r[1] == KIND_MONGE_RIDGE), default=tops[0][0])
    ladder = [r for r in rungs if (ridge if r[1] == KIND_MONGE_RIDGE_LONG else r[0]) < tops[0][0]]
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
def _monge_rung(points, field, p, nbr, quad, circular, frame):
    """Monge quadric over ``p`` and ``nbr`` (``circular`` rounds of the circular correction),
    packed like the normal-constrained quadric.

    ``frame`` (shape (3, 3)) receives the fit's unit normal, the principal direction of the
    curvature smaller in magnitude (along a ridge) and the one across it, as rows.

    Returns
    -------
    status, h, distance, k1, k2, design, side
        Fit status, coordinate unit, RMS residual distance (input units), the curvatures
        at p's foot point, signed against ``field[p]`` (the quadric is negated to agree),
        :func:`one_sided` and, where that exceeds :data:`BORDER_SIDE`,
        :func:`design_spread` (else 0).
    """
    # Neighbors without a normal are outliers (curvature.fitting.outliers): left out.
    keep = np.empty(nbr.shape[0], nbr.dtype)
    count = 0
    for i in range(nbr.shape[0]):
        if np.isfinite(field[nbr[i], 0]):
            keep[count] = nbr[i]
            count += 1
    if count < 6:
        return 1, 0.0, np.nan, np.nan, np.nan, np.inf, 0.0
    xs, h = gather_local(points, p, keep[:count], True)
    if not h > 0.0:
        return 2, 0.0, np.nan, np.nan, np.nan, np.inf, 0.0
    w, axes = principal_axes(xs)
    if not spans_surface(w):
        return 2, h, np.nan, np.nan, np.nan, np.inf, 0.0
    # (the design only where the patch may be cut by the border: it costs a 6 x 6 solve)
    side = one_sided(xs, axes)
    design = design_spread(xs, axes) if side > BORDER_SIDE else 0.0
    a, b, c, ok = fit_monge(xs, axes, circular)
    if not ok:
        return 2, h, np.nan, np.nan, np.nan, np.inf, 0.0
    x0, found = foot_point(a, b, c, MAX_FOOT_DIST)
    if not found:
        return 3, h, np.nan, np.nan, np.nan, np.inf, 0.0
    g = gradient_at(a, b, x0)
    n_p = field[p]
    if g[0] * n_p[0] + g[1] * n_p[1] + g[2] * n_p[2] < 0.0:
        a, b, c, g = -a, -b, -c, -g
    c1, c2, n, d1, d2 = shape_operator(g, 2.0 * a)
    along, across = (d2, d1) if abs(c2) < abs(c1) else (d1, d2)
    for i in range(3):
        frame[0, i], frame[1, i], frame[2, i] = n[i], along[i], across[i]
    quad[0], quad[1], quad[2] = a[0, 0], a[1, 1], a[2, 2]
    quad[3], quad[4], quad[5] = a[0, 1], a[0, 2], a[1, 2]
    quad[6], quad[7], quad[8] = b[0], b[1], b[2]
    quad[9] = c
    return OK, h, sampson_rms(a, b, c, xs) * h, c1 / h, c2 / h, design, side


@njit(cache=True)
def _off_centre(points, p, sub):
    """Distance of the centroid of ``points[sub]`` from ``points[p]`` over their RMS distance
    from it: 0 for a patch centred on its anchor, 0.6 for a half-disk around it."""
    cx, cy, cz, sq = 0.0, 0.0, 0.0, 0.0
    for i in sub:
        dx = points[i, 0] - points[p, 0]
        dy = points[i, 1] - points[p, 1]
        dz = points[i, 2] - points[p, 2]
        cx += dx
        cy += dy
        cz += dz
        sq += dx * dx + dy * dy + dz * dz
    m = sub.shape[0]
    if sq <= 0.0:
        return 0.0
    return np.sqrt(cx * cx + cy * cy + cz * cz) / m / np.sqrt(sq / m)


@njit(cache=True)
def one_sided(xs, axes):
    """How far local points lie to one side of the origin (the anchor): the larger of their
    mean tangent coordinates over that coordinate's RMS (about 1 / sqrt(m) inside a cloud,
    0.85 for a half-disk).

    Parameters
    ----------
    xs : ndarray, shape (m, 3)
        Local points relative to the anchor (:func:`~.kernels.gather_local`).
    axes : ndarray, shape (3, 3)
        Their principal axes (columns, ascending spread): the tangent plane is the last two.
    """
    m = xs.shape[0]
    side = 0.0
    for ax in (2, 1):
        total, square = 0.0, 0.0
        for i in range(m):
            t = xs[i, 0] * axes[0, ax] + xs[i, 1] * axes[1, ax] + xs[i, 2] * axes[2, ax]
            total += t
            square += t * t
        if square > 0.0:
            side = max(side, abs(total) / np.sqrt(square * m))
    return side


@njit(cache=True)
def design_spread(xs, axes):
    """sqrt(m) times the largest standard error of the Hessian terms (2a, b, 2c) of a
    quadratic height fit over local points, per unit of noise, in their RMS unit
    (:data:`DESIGN_ISOTROPIC` for a uniformly filled disk; inf for a degenerate design).

    Parameters
    ----------
    xs : ndarray, shape (m, 3)
        Local points, scaled to unit RMS distance (:func:`~.kernels.gather_local`).
    axes : ndarray, shape (3, 3)
        Their principal axes (columns, ascending spread): the tangent plane is the last two.
    """
    m = xs.shape[0]
    gram = np.zeros((6, 6))
    row = np.empty(6)
    for i in range(m):
        u = xs[i, 0] * axes[0, 2] + xs[i, 1] * axes[1, 2] + xs[i, 2] * axes[2, 2]
        v = xs[i, 0] * axes[0, 1] + xs[i, 1] * axes[1, 1] + xs[i, 2] * axes[2, 1]
        row[0], row[1], row[2], row[3], row[4], row[5] = u * u, u * v, v * v, u, v, 1.0
        for r in range(6):
            for c in range(r + 1):
                gram[r, c] += row[r] * row[c]
    lower, ok = cholesky(gram, 1e-12)  # (reads the lower triangle only)
    if not ok:
        return np.inf
    worst = 0.0
    unit = np.empty(6)
    for term, weight in ((0, 4.0), (1, 1.0), (2, 4.0)):
        unit[:] = 0.0
        unit[term] = 1.0
        y = solve_lower(lower, unit)
        worst = max(worst, weight * np.sum(y * y))
    return np.sqrt(m * worst)


@njit(cache=True)
def _ridge_patch(points, p, nbr, count, frame, aspect):
    """The ``count`` points of ``nbr`` nearest to p in the metric that shrinks distances along
    ``frame[1]`` (a ridge's direction) by ``aspect``, and the RMS spread of
    their offsets across it, times sqrt 2 (the RMS distance of an isotropic patch of that
    width, the ``h`` of :func:`scale_sigma`)."""
    pool = nbr.shape[0]
    metric = np.empty(pool)
    px, py, pz = points[p, 0], points[p, 1], points[p, 2]
    for i in range(pool):
        x, y, z = points[nbr[i], 0] - px, points[nbr[i], 1] - py, points[nbr[i], 2] - pz
        a = (x * frame[1, 0] + y * frame[1, 1] + z * frame[1, 2]) / aspect
        b = x * frame[2, 0] + y * frame[2, 1] + z * frame[2, 2]
        c = x * frame[0, 0] + y * frame[0, 1] + z * frame[0, 2]
        metric[i] = a * a + b * b + c * c
    bound = np.partition(metric.copy(), count - 1)[count - 1]
    out = np.empty(count, nbr.dtype)
    used = 0
    ss = 0.0
    for i in range(pool):
        if metric[i] <= bound and used < count:
            out[used] = nbr[i]
            x, y, z = points[nbr[i], 0] - px, points[nbr[i], 1] - py, points[nbr[i], 2] - pz
            b = x * frame[2, 0] + y * frame[2, 1] + z * frame[2, 2]
            ss += b * b
            used += 1
    return out[:used], np.sqrt(2.0 * ss / max(used, 1))


@njit(cache=True)
def _to_unit(quad, h, unit):
    """Rescale a packed quadric (:data:`N_QUAD`) held in coordinates of unit ``h`` to unit
    ``unit``, in place; returns ``unit``. F is defined up to scale, so the quadratic terms
    scale by (unit / h)^2 and the linear ones by unit / h."""
    ratio = unit / h
    for q in range(6):
        quad[q] *= ratio * ratio
    for q in range(6, 9):
        quad[q] *= ratio
    return unit


@njit(cache=True)
def _store_rung(row, st, c1, c2, d, h, spread, inflate, misfit, positional):
    """One rung's fit into its row of :func:`ladder_estimates`' ``out`` (left unusable where
    the fit failed or its curvature is not supported)."""
    if st != OK or not supported(c1, c2, h):
        return
    # A height fit within noise comparable to its patch is biased, not noisy: a last
    # resort (ok = 2), used only where no other fit is.
    if spread == 0.0:
        spread = h
    limited = positional and d > MONGE_NOISE_LIMIT * spread
    row[0] = 2.0 if limited else 1.0
    row[1] = c1
    row[2] = c2
    row[3] = d
    row[4] = h
    row[5] = spread
    row[6] = inflate
    row[7] = misfit


@njit(cache=True)
def _ridge_rung(points, field, p, nbr, s, kind, frame, quad, row, turn=None):
    """A ridge rung's fit (``kind``, ``s`` points) at anchor p into ``quad`` and ``row`` (as
    :func:`ladder_estimates`' ``out``), its patch stretched along ``frame[1]`` (the
    directions of the circular rung that framed it, :func:`_monge_rung`); not used where the
    normals ``turn`` (if given) do not turn for it across the ridge (:func:`_turn_agrees`)."""
    row[0] = 0.0
    row[6] = 1.0
    row[7] = 0.0
    long = kind == KIND_MONGE_RIDGE_LONG
    pool_size = RIDGE_LONG_POOL if long else \
        RIDGE_SHORT_POOL if kind == KIND_MONGE_RIDGE_SHORT else RIDGE_POOL
    patch, spread = _ridge_patch(points, p, nbr[:min(nbr.shape[0], pool_size)], s, frame,
                                 RIDGE_LONG_ASPECT if long else RIDGE_ASPECT)
    scratch = np.empty((3, 3))  # the ridge rung's own frame, unused
    st, h, d, c1, c2, design, side = _monge_rung(points, field, p, patch, quad,
                                                 CIRCULAR_ROUNDS, scratch)
    inflate = 1.0
    if side > BORDER_SIDE:
        inflate = max(1.0, design / (RIDGE_DESIGN_SLACK *
                                     (DESIGN_RIDGE_LONG if long else DESIGN_RIDGE)))
    if st == OK and spread > 0.0:
        h = _to_unit(quad, h, spread)
    # (h is now the patch's RMS width across the ridge, over which the normals turn)
    if turn is not None and st == OK and \
            not _turn_agrees(turn, p, patch, max(abs(c1), abs(c2)), h):
        st = DEGENERATE
    _store_rung(row, st, c1, c2, d, h, spread, inflate, 0.0, True)


@njit(cache=True)
def turn_supports(field, ref, nbr, k, h):
    """Whether the normals of ``nbr`` turn from ``ref`` enough for a curvature ``k`` over RMS
    radius ``h`` (:data:`TURN_GUARD`).

    Parameters
    ----------
    field : ndarray, shape (n, 3)
        Unit normals, sign arbitrary (NaN: left out).
    ref : ndarray, shape (3,)
        The unit normal at the anchor the angles are read from.
    nbr : ndarray, shape (m,)
    k, h : float
        The largest principal curvature's size, and the points' RMS distance from the anchor.

    Returns
    -------
    bool
        True also where fewer than 8 normals are known.
    """
    if k * h <= TURN_SLACK:  # (most rungs: no angle needed)
        return True
    turned, _ = _turned(field, ref, nbr)
    return turned < 0.0 or k * h <= TURN_GUARD * turned + TURN_SLACK


@njit(cache=True)
def _turned(field, ref, nbr):
    """The 90th percentile of the angles between ``ref`` and the normals ``field[nbr]``
    (sign arbitrary, NaN left out), radians (-1 where fewer than 8 are known), and the sum of
    those normals, each turned to the side of ``ref``, shape (3,)."""
    dots = np.empty(nbr.shape[0])
    total = np.zeros(3)
    c = 0
    for i in range(nbr.shape[0]):
        n = field[nbr[i]]
        dot = ref[0] * n[0] + ref[1] * n[1] + ref[2] * n[2]
        if np.isfinite(dot):
            dots[c] = min(abs(dot), 1.0)
            total += n if dot >= 0.0 else -n
            c += 1
    if c < 8:
        return -1.0, total
    # the 90th percentile of the angles is the arccosine of the 10th of the cosines
    kth = c - 1 - int(0.9 * (c - 1))
    return np.arccos(np.partition(dots[:c], kth)[kth]), total


@njit(cache=True)
def _turn_agrees(turn, p, nbr, k, h):
    """:func:`turn_supports` read from both p's own ``turn`` normal and the mean of the
    normals of ``nbr`` (each turned to the side of p's first). By a thin wall's border p's
    12-point PCA normal may reach a point of the other face: tilted 58 degrees from its
    neighbors', it saw them all turned and passed a 48-point rung reading 22.7 on a flat face
    (the rung's own fitted normal was 44 degrees off there too)."""
    kh = k * h
    if kh <= TURN_SLACK:
        return True
    ref = turn[p]
    turned, mean = _turned(turn, ref, nbr)
    if turned < 0.0:
        return True
    if kh > TURN_GUARD * turned + TURN_SLACK:
        return False
    mean /= np.sqrt(mean[0] * mean[0] + mean[1] * mean[1] + mean[2] * mean[2])
    # Read from the mean, every angle is at least the one from p's normal less the angle
    # between the two: most anchors need no second reading.
    apart = np.arccos(min(abs(mean[0] * ref[0] + mean[1] * ref[1] + mean[2] * ref[2]), 1.0))
    if kh <= TURN_GUARD * (turned - apart) + TURN_SLACK:
        return True
    return turn_supports(turn, mean, nbr, k, h)


@njit(cache=True)
def ladder_estimates(points, field, p, nbr, ladder, kinds, quads, out, fit_long=True,
                     turn=None):
    """Every rung's fit at one anchor (rungs not smaller than the full list are skipped; the
    long ridge rung only with ``fit_long``).

    Parameters
    ----------
    points, field : ndarray, shape (n, 3)
    p : int
    nbr : ndarray, shape (k,)
        Neighbors of p sorted by distance (p not listed).
    ladder, kinds : ndarray, shape (l,), int64
    quads : ndarray, shape (l, N_QUAD)
        Output: each rung's packed quadric.
    out : ndarray, shape (l, 8)
        Output per rung: ok (1; 2 for a Monge rung over the noise limit,
        :data:`MONGE_NOISE_LIMIT`; 0 for none), k1, k2, residual distance, h (the quadric's
        unit: for a ridge rung its width across the ridge), the spread its standard error
        uses (h), the factor its standard error grows by where its patch is cut by
        the cloud's border (Monge rungs, :data:`DESIGN_SLACK` or :data:`RIDGE_DESIGN_SLACK`;
        else 1) and the normal misfit of a normal-quadric rung (0 for the others).
    fit_long : bool
        Whether to fit the long ridge rung (else it is left unusable; :func:`_ridge_rung` fits
        it later from the frame returned).
    turn : ndarray, shape (n, 3), optional
        Normals read over few neighbors (:data:`TURN_MONGE_K`, sign arbitrary): a circular,
        isotropic or ridge Monge rung is not used where they do not turn for its curvature
        (:func:`_turn_agrees`); None: not checked.

    Returns
    -------
    ridge_frame : ndarray, shape (3, 3)
        The frame the long ridge rung's patch is stretched along (NaN where none framed it).
    """
    origin = np.zeros(3)
    frame = np.empty((3, 3))
    ridge_frame = np.full((3, 3), np.nan)
    framed = False  # whether frame holds the directions of a circular Monge rung
    nested = nested_rungs(kinds, 0)
    for li in range(ladder.shape[0]):
        out[li, 0] = 0.0
        out[li, 6] = 1.0
        out[li, 7] = 0.0
        s = ladder[li]
        spread = 0.0
        inflate = 1.0
        misfit = 0.0
        if kinds[li] == KIND_MONGE_RIDGE or kinds[li] == KIND_MONGE_RIDGE_SHORT or \
                kinds[li] == KIND_MONGE_RIDGE_LONG:
            # A ridge rung needs the directions of a smaller fit and a list twice its size
            # (the long one its whole pool, or every point of the cloud).
            long = kinds[li] == KIND_MONGE_RIDGE_LONG
            if long and framed:
                ridge_frame[:] = frame
            wanted = not long or fit_long and _long_pool(nbr.shape[0], points.shape[0])
            if framed and 2 * s <= nbr.shape[0] and wanted:
                _ridge_rung(points, field, p, nbr, s, kinds[li], frame, quads[li], out[li],
                            turn)
            continue
        elif s >= nbr.shape[0]:
            continue
        elif kinds[li] != KIND_NORMAL_QUADRIC:
            if nested[li] >= 0 and out[nested[li], 0] == 0.0:
                # Where the circular rung inside it failed (a line, a cluster of
                # duplicates), a wider one fits whatever else it reaches.
                continue
            rounds = CIRCULAR_ROUNDS if kinds[li] == KIND_MONGE_CIRCULAR else 0
            st, h, d, c1, c2, design, side = _monge_rung(points, field, p, nbr[:s],
                                                         quads[li], rounds, frame)
            if side > BORDER_SIDE:  # a patch cut by the cloud's border
                inflate = max(1.0, design / (DESIGN_SLACK * DESIGN_ISOTROPIC))
            if turn is not None and st == OK and \
                    not _turn_agrees(turn, p, nbr[:s], max(abs(c1), abs(c2)), h):
                st = DEGENERATE
            if st == OK and kinds[li] == KIND_MONGE_CIRCULAR:
                # A ridge's direction: its curvature well below the one across it.
                small, big = min(abs(c1), abs(c2)), max(abs(c1), abs(c2))
                framed = small <= RIDGE_RATIO * big
        else:
            st, h, misfit, d = regress_normal_quadric(points, field, p, nbr[:s], True,
                                                      quads[li])
            if st == OK:
                st, c1, c2, _, _, _ = curvature_from_quadric(quads[li], h, origin, FOOT_LIMIT)
                if st == OK and not turn_supports(field, field[p], nbr[:s],
                                                  max(abs(c1), abs(c2)), h):
                    st = DEGENERATE
        _store_rung(out[li], st, c1, c2, d, h, spread, inflate, misfit,
                    kinds[li] != KIND_NORMAL_QUADRIC)
    return ridge_frame


@njit(cache=True)
def _long_pool(listed, n):
    """Whether a list of ``listed`` neighbors in a cloud of ``n`` points holds the long ridge
    rung's pool (:data:`RIDGE_LONG_POOL`, or every other point)."""
    return listed >= min(RIDGE_LONG_POOL, n - 1)


@njit(cache=True)
def _agree(est, sg, a, b, gamma, part=1):
    """Whether fits ``a`` and ``b`` agree within ``gamma`` times the sum of their sigmas, in k1
    and k2 (``part`` 1) or in the curvature smaller in magnitude (:data:`ALONG`); in the
    larger within :data:`NESTED_AGREEMENT` times their combined sigma (:data:`ACROSS`)."""
    tol = gamma * (sg[a] + sg[b])
    if part == 1:
        return abs(est[a, 1] - est[b, 1]) <= tol and abs(est[a, 2] - est[b, 2]) <= tol
    small_a = abs(est[a, 1]) < abs(est[a, 2])
    small_b = abs(est[b, 1]) < abs(est[b, 2])
    if part == ACROSS:
        small_a, small_b = not small_a, not small_b
        tol = NESTED_AGREEMENT * np.sqrt(sg[a] * sg[a] + sg[b] * sg[b])
    return abs(est[a, 1 if small_a else 2] - est[b, 1 if small_b else 2]) <= tol


@njit(cache=True)
def _lepski(est, sg, grow, gamma, growth, first_top, witness, nested, peer, long_rung=-1,
            confirm=-1):
    """Index of the fit to keep: the largest whose k1 and k2 agree with those of every smaller
    fit within ``gamma`` times the sum of both sigmas, and whose sigma is at most ``growth``
    times the smallest sigma below it (a ladder rung: :data:`RUNG_GROWTH` times; -1 when none
    is usable); the growth test reads ``grow``
    (shape (l + t,)): ``sg``, but for the tops the sigma of their distance to a round
    shape of their curvature (:data:`SIGMA_GROWTH`). A top above the first
    (index above ``first_top``) must also agree with the top just below it within
    :data:`TOP_AGREEMENT` times their combined sigma: the two fit the same model to nested
    patches, so their noise is shared and a small difference already shows a bias; so must a
    circular Monge rung with the one below it (``nested``, :func:`nested_rungs`, within
    :data:`NESTED_AGREEMENT`). A fit r judges a larger fit c only where ``witness[c, r]``,
    and only in the curvatures it names; a sigma r not ``peer[c, r]`` counts
    :data:`RIDGE_GROWTH` times in c's growth test (:func:`_witnesses`), or
    :data:`RIDGE_LONG_GROWTH` times where c is ``long_rung`` (the long ridge rung's index).
    A rung below ``confirm`` (the widest circular rung's index, -1: none) does not turn down a
    fit above it where that rung leaves its disagreement unconfirmed (:func:`_unconfirmed`).

    Each candidate is compared with every smaller rung directly, not with a running intersection, so
    one chance disagreement between two noisy small fits does not stop the selection at the smallest
    of them; and the smallest rung (24 points, the noisiest) can only turn down the next (and the
    ridge rung, as narrow as itself across the ridge): alone it
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
            allowed = 1.0 if peer[c, r] else \
                RIDGE_LONG_GROWTH if c == long_rung else RIDGE_GROWTH
            smallest = min(smallest, grow[r] * allowed)
            if witness[c, r] == 0:
                continue
            if not _agree(est, sg, c, r, gamma, witness[c, r]):
                if r < confirm < c and _unconfirmed(est, sg, c, confirm):
                    continue  # a chance reading of a smaller patch
                agrees = False
                break
        if agrees and c > first_top and np.isfinite(sg[c - 1]):
            agrees = _pair_bias(est, sg, c, c - 1, TOP_AGREEMENT) == 0.0
        r = nested[c]
        if agrees and r >= 0 and np.isfinite(sg[r]):
            agrees = _pair_bias(est, sg, c, r, NESTED_AGREEMENT) == 0.0
        limit = growth if c >= first_top else min(growth, RUNG_GROWTH)
        if agrees and grow[c] <= limit * smallest:
            return c
    return -1


@njit(cache=True)
def _unconfirmed(est, sg, c, wide):
    """Whether the widest circular rung ``wide`` reads no curvature beyond
    :data:`CONFIRM_FLAT` of its sigma and agrees with fit ``c`` within
    :data:`CONFIRM_AGREEMENT` times their summed sigmas: a smaller rung that disagrees with c
    then read a chance bump of the noise."""
    if not np.isfinite(sg[wide]) or \
            max(abs(est[wide, 1]), abs(est[wide, 2])) > CONFIRM_FLAT * sg[wide]:
        return False
    return _agree(est, sg, c, wide, CONFIRM_AGREEMENT)


@njit(cache=True)
def _pair_bias(est, sg, best, r, z):
    """Disagreement of fit ``best`` with fit ``r`` beyond ``z`` times their combined errors:
    of the larger of k1's and k2's."""
    slack = z * np.sqrt(sg[r] * sg[r] + sg[best] * sg[best])
    d1 = abs(est[best, 1] - est[r, 1]) - slack
    d2 = abs(est[best, 2] - est[r, 2]) - slack
    return max(0.0, d1, d2)


@njit(cache=True)
def _bias(est, sg, best, peer):
    """Bias of fit ``best`` as :func:`_least_error` weighs it: the largest disagreement of
    its k1 or k2 with a smaller usable fit (``peer[best]``, :func:`_witnesses`) beyond
    :data:`BIAS_SLACK` times their errors."""
    out = 0.0
    for r in range(best):
        if np.isfinite(sg[r]) and peer[best, r]:
            out = max(out, _pair_bias(est, sg, best, r, BIAS_SLACK))
    return out


@njit(cache=True)
def _reported_bias(est, sg, best, col):
    """Bias of fit ``best``'s k1 (``col`` 1) or k2 (2) for its standard error (the
    selection reads :func:`_bias`).

    Each smaller usable fit r gives ``d_r^2 - v_r``, an unbiased estimate of the squared bias
    (d_r their disagreement, v_r its variance from both fits' sigmas). Both are extrapolated
    to zero size: a bias growing as h^2 (the first term a quadric cannot follow) differs
    between patches of h_b and h_r by (1 - h_r^2 / h_b^2) of the wider one's (a share of at
    least :data:`BIAS_SHARE_MIN`), so a difference with the next smaller fit (half the points,
    h^2 halved) is half of it. The estimates are averaged with weights ``1 / v_r^2`` (d_r^2's
    variance is about ``2 v_r^2``); the square root of a positive mean is returned. Until
    stop 40 the largest excess of any d_r over 1.5 sqrt(v_r) was reported: a 24-point rung's
    chance miss, with a sigma up to a hundred times the kept fit's, became the kept fit's
    bias (a 10,000-point sphere at 0.1 % noise: half the points reported 0.02 to 2 for errors
    of 0.0024; docs/accuracy.md section 10)."""
    hb = est[best, 5] * est[best, 5]
    num = 0.0
    den = 0.0
    for r in range(best):
        if not np.isfinite(sg[r]):
            continue
        share = 1.0 - est[r, 5] * est[r, 5] / hb if hb > 0.0 else 1.0
        grow = 1.0 / max(share, BIAS_SHARE_MIN)
        d = grow * (est[best, col] - est[r, col])
        v = grow * grow * (sg[r] * sg[r] + sg[best] * sg[best])
        if not v > 0.0:
            continue
        w = 1.0 / (v * v)
        num += w * (d * d - v)
        den += w
    if den == 0.0 or not num > 0.0:
        return 0.0
    return np.sqrt(num / den)


@njit(cache=True)
def _least_error(est, sg, best, kinds, gamma, peer, confirm=-1):
    """Fit ``best`` (Lepski's choice) or a smaller positional rung that shows best biased.

    Lepski's rule passes a wide fit whose bias hides within the noise of the smaller fits
    (a blade's leading edge, k = 20: the 96-point normal fit passes against the 48-point rung
    and reads 2.5 off). A Monge rung r (circular or ridge; they do not depend on the stage-1
    normals, whose smoothing biases every normal fit alike) above the first replaces it where
    their disagreement beyond :data:`SWITCH_SLACK` times ``gamma`` combined errors, d, makes
    best's expected error ``sigma_b^2 + d^2`` exceed r's own, ``sigma_r^2 + bias_r^2`` (bias_r
    against the fits below r, :func:`_bias`), and r agrees with every other usable Monge rung
    below best within ``gamma`` (a chance outlier among them shows nothing); of several such
    the least. Without a disagreement nothing switches: a smaller sigma alone does not make a
    smaller fit better (the normal fits' sigmas are below the tops' on a torus, their errors
    above). Only ``peer`` pairs count (:func:`_witnesses`): a circular rung wider across a
    ridge than the ridge rung neither replaces it nor shows it biased, and a rung below
    ``confirm`` does not where :func:`_unconfirmed` says its disagreement is chance.
    """
    keep = best
    least = np.inf
    top = min(best, kinds.shape[0])
    for r in range(1, top):
        if not np.isfinite(sg[r]) or kinds[r] == KIND_NORMAL_QUADRIC or not peer[best, r]:
            continue
        shown = _pair_bias(est, sg, best, r, gamma * SWITCH_SLACK)
        if shown == 0.0 or r < confirm < best and _unconfirmed(est, sg, best, confirm):
            continue
        e = sg[r] * sg[r] + _bias(est, sg, r, peer) ** 2
        if not (e < least and e < sg[best] * sg[best] + shown * shown):
            continue
        consistent = True
        for m in range(top):
            if m != r and np.isfinite(sg[m]) and kinds[m] != KIND_NORMAL_QUADRIC and \
                    peer[max(m, r), min(m, r)] and not _agree(est, sg, r, m, gamma):
                consistent = False
                break
        if consistent:
            keep, least = r, e
    return keep


@njit(cache=True)
def nested_rungs(kinds, ntop):
    """For each fit, the smaller fit of the same model over a part of its patch that it must
    agree with within :data:`NESTED_AGREEMENT` combined standard errors in Lepski's rule (-1:
    none): each circular Monge rung's next smaller one, but not the 24-point rung (chance
    readings). Shape (l + t,), int64; the tops' own nesting is :data:`TOP_AGREEMENT`'s.
    """
    levels = kinds.shape[0]
    nested = np.full(levels + ntop, -1, np.int64)
    last = -1
    for li in range(levels):
        if kinds[li] == KIND_MONGE_CIRCULAR:
            if last > 0:
                nested[li] = last
            last = li
    return nested


@njit(cache=True)
def _framing_rung(est, sg, kinds, c):
    """The widest usable circular rung below ridge rung ``c`` (the one whose directions framed
    it; -1: none)."""
    for r in range(c - 1, -1, -1):
        if kinds[r] == KIND_MONGE_CIRCULAR and np.isfinite(sg[r]) and est[r, 0] == 1.0:
            return r
    return -1


@njit(cache=True)
def _significant_ridge(est, sg, kinds, c):
    """Whether the rung that framed ridge rung ``c`` reads its larger curvature above
    :data:`RIDGE_SIGNIFICANCE` times its sigma."""
    r = _framing_rung(est, sg, kinds, c)
    return r >= 0 and max(abs(est[r, 1]), abs(est[r, 2])) > RIDGE_SIGNIFICANCE * sg[r]


@njit(cache=True)
def _turn(est, r):
    """How far fit ``r`` turns its normal over its patch: its larger curvature times its RMS
    radius (rad)."""
    return max(abs(est[r, 1]), abs(est[r, 2])) * est[r, 5]


@njit(cache=True)
def _tight_framing(est, sg, kinds, c):
    """The rung that framed ridge rung ``c`` where it reads a significant curvature turning
    its normal by more than :data:`RIDGE_TURN` (-1: none)."""
    if not _significant_ridge(est, sg, kinds, c):
        return -1
    r = _framing_rung(est, sg, kinds, c)
    return r if _turn(est, r) > RIDGE_TURN else -1


@njit(cache=True)
def _tight_ridge(est, sg, kinds, c):
    """Whether usable ridge rung ``c`` reads a significant, tight, nearly cylindrical ridge
    (:data:`RIDGE_CYLINDRICAL`, :data:`RIDGE_TURN`)."""
    if not np.isfinite(sg[c]):
        return False
    big = max(abs(est[c, 1]), abs(est[c, 2]))
    return min(abs(est[c, 1]), abs(est[c, 2])) < RIDGE_CYLINDRICAL * big and \
        _tight_framing(est, sg, kinds, c) >= 0


@njit(cache=True)
def _tight_cap(est, sg, kinds, c):
    """Whether the circular rung below ridge rung ``c`` (:func:`_framing_rung`) reads a
    significant, tight cap: its curvatures alike (the smaller above :data:`RIDGE_RATIO` of
    the larger: no ridge is framed) and turning its normal by more than :data:`RIDGE_TURN`
    over its patch (a filleted box's corners, whose stage-1 normals are smoothed as a tight
    ridge's are). Not where the 24-point rung frames alone (the 48-point one unusable): its
    chance readings took the normal fits from a 10,000-point cylinder at 0.5 % noise (+7 %)."""
    r = _tight_framing(est, sg, kinds, c)
    return r > 0 and min(abs(est[r, 1]), abs(est[r, 2])) > \
        RIDGE_RATIO * max(abs(est[r, 1]), abs(est[r, 2]))


@njit(cache=True)
def _witnesses(est, sg, kinds, t_status, t_model, levels):
    """Which smaller fit judges which in Lepski's rule, and whose sigma and bias count.

    Every smaller fit judges a larger one in k1 and k2, except:

    - the 24-point rung (the noisiest), which judges only the next rung;

    beside a significant ridge (:func:`_significant_ridge`; elsewhere chance readings):

    - the 24-point rung judges the ridge rung too, whose patch is as narrow across the ridge
      as its own;
    - the wider circular rungs judge the ridge rung only in the curvature along the ridge
      (:data:`ALONG`): across it their patches reach farther round a leading edge and read
      it lower than the ridge rung does (the bench blade's 48-point rung 13 to 18 for 20).
      They are not its ``peer``: the growth test allows the ridge rung
      :data:`RIDGE_GROWTH` times their sigma, :func:`_least_error` neither lets them replace
      it nor weighs their disagreement as its bias;
    - the ridge rung judges the short ridge rung in the curvature across the ridge only
      (:data:`ACROSS`);
    - every rung below the long ridge rung is wider across the ridge: the 24-point rung
      judges it in full, the other positional rungs along the ridge only, and none is its
      peer (:data:`RIDGE_LONG_GROWTH`);

    and at the tops:

    - a normal-quadric rung whose normals misfit the quadric more than a top's polynomial
      normal field misfits them (:data:`WITNESS_MISFIT`) does not judge that top: the top
      kept the field because the quadric misfits its patch, and where the quadric misfits the
      rung's smaller patch too, the rung's curvature carries that misfit, not the top's bias.
      The growth test still counts the rung's sigma.

    Returns
    -------
    witness : ndarray, shape (l + t, l + t), int8
        ``witness[c, r]``: 0 (r does not judge c), 1 (k1 and k2), :data:`ALONG` or
        :data:`ACROSS` (:func:`_agree`).
    peer : ndarray, shape (l + t, l + t), bool
        Whether r's sigma counts fully in c's growth test and r may show c biased.
    """
    count = levels + t_status.shape[0]
    witness = np.ones((count, count), np.int8)
    witness[2:, 0] = 0  # the 24-point rung judges only the next (_lepski)
    peer = np.ones((count, count), np.bool_)
    for c in range(levels):
        if kinds[c] != KIND_MONGE_RIDGE or not _significant_ridge(est, sg, kinds, c):
            continue
        witness[c, 0] = 1  # as narrow across the ridge as the ridge rung
        for r in range(1, c):
            if kinds[r] == KIND_MONGE_CIRCULAR:  # wider across it
                witness[c, r] = ALONG
                peer[c, r] = False
        for r in range(c + 1, levels):
            if kinds[r] == KIND_MONGE_RIDGE_SHORT:  # shorter along it, wider across
                witness[r, c] = ACROSS
            elif kinds[r] == KIND_MONGE_RIDGE_LONG:  # narrower across than every rung below
                witness[r, 0] = 1
                peer[r, 0] = False
                for q in range(1, r):
                    if kinds[q] != KIND_NORMAL_QUADRIC:
                        witness[r, q] = ALONG
                        peer[r, q] = False
    for t in range(t_status.shape[0]):
        if t_status[t] != OK or t_model[t] != MODEL_FIELD:
            continue
        for li in range(levels):
            if kinds[li] == KIND_NORMAL_QUADRIC and \
                    est[li, 7] > WITNESS_MISFIT * est[levels + t, 7]:
                witness[levels + t, li] = 0
    return witness, peer


@njit(parallel=True, cache=True)
def multiscale_anchor_fits(points, field, anchors, indptr, indices, nfr_ratio, ladder, kinds,
                           tops, strides, gamma, growth, calib, side_limit, coef, scale, frame,
                           quad, quad_scale, model, residual, status, chosen, sigma, bias,
                           longer, turn=None):
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
    side_limit : float
        A top wider than :data:`SIDE_FROM` is not fitted where the centroid of its points lies
        farther than this share of their RMS distance from the anchor (:func:`_off_centre`;
        inf: always fitted).
    coef, scale, frame, quad, quad_scale, model, residual, status
        Outputs as for ``nfr_anchor_fits``: the kept model.
    chosen : ndarray, shape (a,), int64
        Output: neighbors of the kept fit (the anchor takes part besides): the patch's size,
        strided tops included.
    sigma : ndarray, shape (a,)
        Output: the kept fit's standard error of curvature (inf when none was usable), a
        top's read off its distance to the shape of its curvature (``shape_distance`` of
        :func:`~curvature.fitting.normal_field.nfr_anchor_fits_one`).
    bias : ndarray, shape (a, 2)
        Output: the kept fit's bias of k1 and of k2 as the smaller fits show it
        (:func:`_reported_bias`; 0 when none disagrees beyond their errors).
    longer : ndarray, shape (a,), bool
        Output: whether the anchor would fit the long ridge rung (:data:`RIDGE_LONG_TURN`)
        but its list is shorter than :data:`RIDGE_LONG_POOL` (and than the cloud): fitted
        again from such a list, it may keep that rung (every other fit reads the same).
    turn : ndarray, shape (n, 3), optional
        As for :func:`ladder_estimates`.
    """
    levels = ladder.shape[0]
    ntop = tops.shape[0]
    nested = nested_rungs(kinds, ntop)
    long_rung = -1
    confirm = -1  # the widest circular rung (CONFIRM_SIZE)
    for li in range(levels):
        if kinds[li] == KIND_MONGE_RIDGE_LONG:
            long_rung = li
        elif kinds[li] == KIND_MONGE_CIRCULAR and ladder[li] >= CONFIRM_SIZE:
            confirm = li
    for j in prange(anchors.shape[0]):
        p = anchors[j]
        nbr = indices[indptr[j]:indptr[j + 1]]
        full = nbr.shape[0]
        quads = np.empty((levels, N_QUAD))
        est = np.empty((levels + ntop, 8))
        # (the long ridge rung only where it is wanted, below: its pool is most of a long list)
        ridge_frame = ladder_estimates(points, field, p, nbr, ladder, kinds, quads, est, False,
                                       turn)
        # Every top's full fit (both models) into scratch rows; the kept one is copied out.
        t_coef = np.empty((ntop,) + coef.shape[1:])
        t_quad = np.empty((ntop, N_QUAD))
        t_frame = np.empty((ntop, 3, 3))
        t_scale, t_qscale, t_resid = np.empty(ntop), np.empty(ntop), np.empty(ntop)
        t_model, t_status = np.empty(ntop, np.int8), np.empty(ntop, np.int8)
        sizes = np.empty(levels + ntop, np.int64)
        sizes[:levels] = ladder
        shape_d = np.empty(ntop)  # each top's distance the growth test reads
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
            if size > SIDE_FROM and _off_centre(points, p, sub) > side_limit:
                # A wide patch far off its anchor (by a cloud's border, or bent away from its
                # tangent plane): its bias there hides within the smaller fits' noise.
                t_status[t] = -1
                continue
            fk1, fk2, fd, fh, fm, fs = nfr_anchor_fits_one(
                points, field, p, sub, nfr_ratio, t_coef[t], t_quad[t], t_frame[t], t,
                t_scale, t_qscale, t_model, t_resid, t_status)
            shape_d[t] = fs
            if t_status[t] == OK and supported(fk1, fk2, fh):
                est[row, 0] = 1.0
                est[row, 1], est[row, 2], est[row, 3], est[row, 4] = fk1, fk2, fd, fh
                est[row, 5] = fh
                est[row, 6] = 1.0
                est[row, 7] = fm
        sg = np.full(levels + ntop, np.inf)
        grow = np.full(levels + ntop, np.inf)
        for li in range(levels + ntop):
            if est[li, 0] == 1.0:
                s = sizes[li]
                if li >= levels:
                    s = (s + strides[li - levels] - 1) // strides[li - levels]
                sg[li] = scale_sigma(est[li, 3], est[li, 5], s, calib[li]) * est[li, 6]
                grow[li] = sg[li]
                if li >= levels:
                    grow[li] = scale_sigma(shape_d[li - levels], est[li, 5], s, calib[li])
        # Beside no real ridge (RIDGE_SIGNIFICANCE) one ridge rung, from the list a top of
        # k reads: the short one of a refit's 192 neighbors, else the narrow one.
        short_only = tops[ntop - 1] < RIDGE_POOL
        for li in range(levels):
            if (kinds[li] == KIND_MONGE_RIDGE or kinds[li] == KIND_MONGE_RIDGE_SHORT) and \
                    (kinds[li] == KIND_MONGE_RIDGE) == short_only and \
                    not _significant_ridge(est, sg, kinds, li):
                sg[li] = grow[li] = np.inf
        wanted = False  # a long ridge rung (RIDGE_LONG_TURN)
        for li in range(levels):
            if kinds[li] != KIND_MONGE_RIDGE:
                continue
            ridge = _tight_ridge(est, sg, kinds, li)
            if ridge or _tight_cap(est, sg, kinds, li):
                for r in range(levels + ntop):  # no normal fit (RIDGE_TURN)
                    if r >= levels or kinds[r] == KIND_NORMAL_QUADRIC:
                        sg[r] = grow[r] = np.inf
            if ridge:
                wanted = _turn(est, _framing_rung(est, sg, kinds, li)) > RIDGE_LONG_TURN
        longer[j] = False
        if wanted and long_rung >= 0:
            longer[j] = not _long_pool(full, points.shape[0])
            if not longer[j] and 2 * ladder[long_rung] <= full:
                _ridge_rung(points, field, p, nbr, ladder[long_rung], KIND_MONGE_RIDGE_LONG,
                           ridge_frame, quads[long_rung], est[long_rung], turn)
                if est[long_rung, 0] == 1.0:
                    sg[long_rung] = scale_sigma(est[long_rung, 3], est[long_rung, 5],
                                                sizes[long_rung], calib[long_rung])
                    sg[long_rung] *= est[long_rung, 6]
                    grow[long_rung] = sg[long_rung]
        witness, peer = _witnesses(est, sg, kinds, t_status, t_model, levels)
        best = _lepski(est, sg, grow, gamma, growth, levels, witness, nested, peer, long_rung,
                       confirm)
        if best < 0:  # nothing else usable: the noise-limited Monge rungs (ladder_estimates)
            for li in range(levels):
                if est[li, 0] == 2.0:
                    sg[li] = (scale_sigma(est[li, 3], est[li, 5], sizes[li], calib[li])
                              * est[li, 6])
                    grow[li] = sg[li]
            best = _lepski(est, sg, grow, gamma, growth, levels, witness, nested, peer,
                           long_rung, confirm)
        if best > 0:
            best = _least_error(est, sg, best, kinds, gamma, peer, confirm)
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
        bias[j, 0] = bias[j, 1] = 0.0
        if best < 0:
            continue  # nothing usable: the largest top's status stands
        # A top's reported sigma reads its distance to a shape of its own curvature, as the
        # growth test does: a torus's field top, whose paraboloid distance counts the tube's
        # turn, reported 2.6 times its median error; then 1.3 (docs/accuracy.md section 10).
        sigma[j] = grow[best]
        bias[j, 0] = _reported_bias(est, sg, best, 1)
        bias[j, 1] = _reported_bias(est, sg, best, 2)
        if best < levels:
            chosen[j] = ladder[best]
            for r in range(N_QUAD):
                quad[j, r] = quads[best, r]
            quad_scale[j] = est[best, 4]
            model[j] = 1  # MODEL_QUADRIC: read with curvature_from_quadric
            residual[j] = est[best, 3]
            status[j] = OK
